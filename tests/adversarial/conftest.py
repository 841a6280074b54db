"""What the adversarial directory tests share: a real directory server in a thread."""

from __future__ import annotations

import asyncio
import threading

import pytest
from wott_directory import Directory, DirectoryServer, DirectorySettings


class DirectoryThread:
    """A real directory server in a thread with its own event loop."""

    def __init__(self, token: str, db: str = "sqlite://") -> None:
        self.token = token
        self.db = db
        self.loop = asyncio.new_event_loop()
        self.server: DirectoryServer | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        directory = Directory(DirectorySettings(token=self.token), self.db)
        self.server = self.loop.run_until_complete(DirectoryServer(directory).start())
        self._ready.set()
        self.loop.run_forever()

    def start(self) -> DirectoryThread:
        self._thread.start()
        assert self._ready.wait(30), "the directory did not start"
        return self

    @property
    def url(self) -> str:
        assert self.server is not None
        return self.server.url

    def stop(self) -> None:
        assert self.server is not None
        asyncio.run_coroutine_threadsafe(self.server.stop(), self.loop).result(30)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(10)


@pytest.fixture(scope="session")
def directory_thread() -> type[DirectoryThread]:
    """``directory_thread(token, db).start()``: a started ``DirectoryThread`` (stop it yourself)."""
    return DirectoryThread
