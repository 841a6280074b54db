"""A real directory on 127.0.0.1 (free port) in a background thread, driven over HTTP with httpx.

The server runs its own asyncio loop in a thread so tests can be plain
synchronous code that talks HTTP like any client would.
"""

from __future__ import annotations

import asyncio
import copy
import queue
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from typing import Any

import httpx
import pytest
from httpx_sse import connect_sse
from wott_directory import Directory, DirectoryServer, DirectorySettings

TOKEN = "test-token-0123"


class ServerThread:
    def __init__(self, settings: DirectorySettings, db: str = "sqlite://") -> None:
        self.settings = settings
        self.db = db
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self.server: DirectoryServer | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> ServerThread:
        self._thread.start()
        if not self._ready.wait(20):
            raise RuntimeError("directory did not start")
        if self._error:
            raise self._error
        return self

    def _run(self) -> None:
        asyncio.run(self._main())

    async def _main(self) -> None:
        try:
            self.loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self.server = await DirectoryServer(Directory(self.settings, self.db)).start()
        except BaseException as e:  # surfaced to the test by start()
            self._error = e
            self._ready.set()
            return
        self._ready.set()
        await self._stop.wait()
        await self.server.stop()

    @property
    def url(self) -> str:
        assert self.server is not None
        return self.server.url

    @property
    def directory(self) -> Directory:
        assert self.server is not None
        return self.server.directory

    def call(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn()`` (a coroutine function or plain function) on the server's loop."""
        assert self.loop is not None

        async def wrapper() -> Any:
            result = fn()
            if asyncio.iscoroutine(result):
                result = await result
            return result

        fut: Future[Any] = asyncio.run_coroutine_threadsafe(wrapper(), self.loop)
        return fut.result(20)

    def stop(self) -> None:
        if self.loop is not None and self._stop is not None and self._thread.is_alive():
            self.loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(20)


ENGINE_MODULES = {"test_things_api.py", "test_search.py", "test_events.py", "test_expiry_and_storage.py"}
"""Modules whose directories run on SQLite and on PostgreSQL (the session's throw-away cluster,
tests/postgres.py, registered by the root conftest.py); the others on SQLite only."""


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "directory_db" in metafunc.fixturenames and metafunc.definition.path.name in ENGINE_MODULES:
        metafunc.parametrize("directory_db", ["sqlite", "postgresql"], indirect=True)


@pytest.fixture
def directory_db(request: pytest.FixtureRequest) -> str:
    """The database URL a test's directories use: in-memory SQLite, or a fresh PostgreSQL database."""
    if getattr(request, "param", "sqlite") == "postgresql":
        return str(request.getfixturevalue("pg_url"))
    return "sqlite://"


@pytest.fixture
def start_directory(directory_db: str) -> Iterator[Callable[..., ServerThread]]:
    started: list[ServerThread] = []

    def start(db: str | None = None, **settings: Any) -> ServerThread:
        settings.setdefault("token", TOKEN)
        srv = ServerThread(DirectorySettings(**settings), db or directory_db).start()
        started.append(srv)
        return srv

    yield start
    for srv in started:
        srv.stop()


@pytest.fixture
def tdd(start_directory: Callable[..., ServerThread]) -> ServerThread:
    return start_directory()


@pytest.fixture
def http(tdd: ServerThread) -> Iterator[httpx.Client]:
    """A client authorised to write (most tests); use ``anon`` for unauthenticated requests."""
    with httpx.Client(base_url=tdd.url, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=10) as c:
        yield c


@pytest.fixture
def anon(tdd: ServerThread) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=tdd.url, timeout=10) as c:
        yield c


BASE_TD: dict[str, Any] = {
    "@context": "https://www.w3.org/2022/wot/td/v1.1",
    "id": "urn:example:lamp",
    "title": "lamp",
    "securityDefinitions": {"nosec_sc": {"scheme": "nosec"}},
    "security": "nosec_sc",
    "properties": {
        "status": {"type": "string", "forms": [{"href": "https://lamp.example/status"}]},
    },
}


def make_td(thing_id: str | None = "urn:example:lamp", **changes: Any) -> dict[str, Any]:
    """A small valid TD 1.1; ``thing_id=None`` makes it anonymous."""
    td = copy.deepcopy(BASE_TD)
    if thing_id is None:
        td.pop("id")
    else:
        td["id"] = thing_id
    td.update(changes)
    return td


def td_headers() -> dict[str, str]:
    return {"Content-Type": "application/td+json"}


def wait_until(predicate: Callable[[], bool], timeout: float = 10.0, interval: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval)
    return predicate()


@pytest.fixture
def helpers() -> Any:
    class H:
        make_td = staticmethod(make_td)
        td_headers = staticmethod(td_headers)
        wait_until = staticmethod(wait_until)
        token = TOKEN

    return H


class Listener:
    """Reads one SSE stream in a thread; ``get()`` returns the next event."""

    def __init__(self, base_url: str, path: str, headers: dict[str, str] | None = None) -> None:
        self.events: queue.Queue = queue.Queue()
        self.ready = threading.Event()
        self.status = 0
        self.client = httpx.Client(base_url=base_url, timeout=httpx.Timeout(10, read=30))
        self._thread = threading.Thread(target=self._run, args=(path, headers or {}), daemon=True)
        self._thread.start()
        assert self.ready.wait(10), "SSE stream did not open"

    def _run(self, path: str, headers: dict[str, str]) -> None:
        try:
            with connect_sse(self.client, "GET", path, headers=headers) as source:
                self.status = source.response.status_code
                self.content_type = source.response.headers.get("content-type")
                self.ready.set()
                for sse in source.iter_sse():
                    self.events.put(sse)
        except (httpx.HTTPError, RuntimeError):
            pass
        finally:
            self.ready.set()

    def get(self, timeout: float = 10):
        return self.events.get(timeout=timeout)

    def empty_for(self, seconds: float) -> bool:
        try:
            self.events.get(timeout=seconds)
        except queue.Empty:
            return True
        return False

    def close(self) -> None:
        self.client.close()


@pytest.fixture
def listener_cls() -> type[Listener]:
    """The SSE reader class (tests open streams with their own paths and headers)."""
    return Listener
