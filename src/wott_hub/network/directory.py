"""The hub's Thing Description Directory and its registrations into other directories.

Every Thing the hub serves (devices, the hub Thing, replay Things, adopted
WoT devices) is put into the embedded directory when it is exposed and
deleted when it is removed, in the order the hub did it (one worker per
directory, so a put never overtakes the delete before it). The same changes go
to each ``register_to`` directory through a ``Registrar``, with a ttl it
refreshes every ttl/3: a hub that dies leaves its Things there at most ttl
seconds, one that stops cleanly deletes them.

The embedded directory lives in the hub's database (tables ``tdd_things`` and
``tdd_events``, created by the hub's Alembic revision 0002, never by
``create_all``), and is mounted at the host root (``/things``,
``/search/jsonpath``, ``/events``, ``/.well-known/wot``). Its routes are
mounted when the hub is built and the directory opens with the database, a
moment after the TDs are served: a request arriving in between waits for it
(``routes.py``), as the hub's own stream requests wait for the history.

Identity (docs/scale-out.md): every Thing id of a hub carries its hub id
(``urn:wott-hub:<hub-id>:...``). Before registering into a ``register_to``
directory the hub looks its own hub Thing up there: registered by another hub
that is still alive (the registration has not expired and the TD's ``base``,
another address than this hub's, answers with that id), the hub refuses to start
(``Conflict``) instead of overwriting it. A registration left by a crashed run of
the same hub (expired, or its base silent or this hub's own) is taken over.

Writes by other clients: with ``[directory] token`` they need that bearer
token; without one, clients on loopback write freely when the hub listens on
loopback only (the demo), and nobody else can write. The hub itself writes
in-process and needs neither.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

from .config import DirectoryConfig
from .routes import DIRECTORY_PATHS, DirectoryRouter

if TYPE_CHECKING:
    from wott_directory import Directory, Registrar

    from .port import HubPort

__all__ = ["HubDirectory", "OWN_ID_PREFIX"]

log = logging.getLogger("wott_hub.network")

OWN_ID_PREFIX = "urn:wott-hub:"
"""Ids of the TDs any wott-hub builds (devices, the hub Thing, replays), of every hub."""
LEGACY_PREFIXES = ("urn:wott-hub:device:", "urn:wott-hub:hub:", "urn:wott-hub:replay:")
"""Ids of the scheme before hub ids (one hub per directory): a previous run's leftovers."""
LIVENESS_TIMEOUT_S = 3.0

Op = Callable[[], Awaitable[Any]]
UNREGISTER_TIMEOUT_S = 5.0


class _Worker:
    """Runs one directory's writes one at a time, in the order they were asked for."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.queue: asyncio.Queue[Op | None] = asyncio.Queue()
        self.task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self.task = asyncio.create_task(self._run(), name=f"directory-writes:{self.name}")

    def submit(self, op: Op) -> None:
        self.queue.put_nowait(op)

    async def _run(self) -> None:
        while (op := await self.queue.get()) is not None:
            try:
                await op()
            except Exception:  # one refused TD must not stop the others
                log.exception("directory %s: write failed", self.name)
            finally:
                self.queue.task_done()

    async def drain(self) -> None:
        """Wait until every write asked for so far is done."""
        if self.task is not None and not self.task.done():
            await self.queue.join()

    async def stop(self, finish: bool = True) -> None:
        """``finish``: do the writes still queued first; otherwise drop them."""
        if self.task is None:
            return
        if finish:
            self.queue.put_nowait(None)
        else:
            self.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self.task
        self.task = None


class HubDirectory:
    def __init__(self, hub: HubPort, cfg: DirectoryConfig) -> None:
        self.hub = hub
        self.cfg = cfg
        self.directory: Directory | None = None
        self.registrars: list[Registrar] = []
        self._workers: list[tuple[_Worker, Any]] = []  # (worker, the embedded Directory or a Registrar)
        self.router: DirectoryRouter | None = None
        if cfg.enabled:  # mounted now, without importing the directory (see routes.py)
            self.router = DirectoryRouter(hub.http_app)
            hub.add_handlers([(DIRECTORY_PATHS, self.router)])

    @property
    def url(self) -> str | None:
        """The directory's base URL (``/things`` is under it), or None when it is off."""
        return f"{self.hub.http_url}/" if self.cfg.enabled else None

    # --- lifecycle ------------------------------------------------------------------

    async def start(self) -> None:
        for reg in self.cfg.register_to:  # before anything is opened or registered: a refusal leaves nothing
            await self._check_not_taken(reg.url, reg.token)
        try:
            if self.cfg.enabled:
                await self._open_embedded()
            for reg in self.cfg.register_to:
                self._add_registrar(reg.url, reg.token)
            for thing in self.hub.served():
                self.exposed(thing.td)
            if self.directory is not None:  # a client waiting for /things gets the whole fleet
                await self._workers[0][0].drain()
        finally:
            if self.router is not None:
                self.router.open()  # held requests go through (503 if the directory failed)
        for registrar in self.registrars:
            registrar.start()

    async def _open_embedded(self) -> None:
        from wott_directory import Directory, DirectorySettings, directory_handlers
        from wott_directory.settings import is_loopback

        cfg, hub = self.cfg, self.hub
        # the hub's gate checks clients' scoped tokens (wott_hub.security) and hands the directory the
        # hub's own credential instead: the directory then declares and requires bearer for everything
        credential = hub.directory_credential
        token, protect_reads = (credential, True) if credential else (cfg.token, cfg.protect_reads)
        open_writes = token is None and is_loopback(hub.host)
        if token is None and not open_writes:
            log.warning("the hub's directory accepts no registrations from others: it listens on %s and "
                        "[directory] token is not set", hub.host)
        settings = DirectorySettings(base_url=f"{hub.http_url}/", title=f"{hub.name} directory",
                                     token=token, open_writes=open_writes,
                                     protect_reads=protect_reads)
        # the hub's database, migrated by the hub (revision 0002 has the directory's tables);
        # without history, a directory in memory that lives as long as the hub
        engine = hub.engine
        directory = Directory(settings, engine if engine is not None else "sqlite://",
                              create_tables=engine is None,
                              td_security=hub.directory_td_security)
        try:
            await directory.start()
        except Exception:
            log.exception("the hub's directory could not be opened; /things answers 503")
            await directory.stop()
            return
        self.directory = directory
        assert self.router is not None  # made with the config's enabled = true
        self.router.install(directory_handlers(directory, prefix=""))
        await self._forget_stale()
        worker = _Worker("embedded")
        worker.start()
        self._workers.append((worker, directory))

    async def _check_not_taken(self, url: str, token: str | None) -> None:
        """``Conflict`` if this hub's Thing id is registered in ``url`` by another live hub."""
        from wott_directory import DirectoryClient
        from wott_directory.client import ProblemError

        from wott_hub.errors import Conflict

        tid = self.hub.hub_thing_id
        client = DirectoryClient(url, token=token, timeout=LIVENESS_TIMEOUT_S)
        try:
            try:
                td = await client.get(tid)
            except (ProblemError, OSError):  # not there (404), or the directory is down: the
                return  # registrar keeps trying, and checks nothing later; nobody to collide with now
            expires = (td.get("registration") or {}).get("expires")
            if isinstance(expires, str):
                with contextlib.suppress(ValueError):
                    when = datetime.fromisoformat(expires)
                    if (when if when.tzinfo else when.replace(tzinfo=UTC)) <= datetime.now(UTC):
                        return
            base = td.get("base")
            if not isinstance(base, str) or base.rstrip("/") == self.hub.http_url.rstrip("/"):
                return  # this hub's own registration, left by a crashed run on the same address
            try:
                resp = await client.http.fetch(f"{base.rstrip('/')}/wot/hub", raise_error=False,
                                               request_timeout=LIVENESS_TIMEOUT_S)
            except OSError:  # its base is silent: a hub that died before its registration expired
                return
            if resp.code == 200:
                with contextlib.suppress(ValueError):
                    if json.loads(resp.body).get("id") == tid:
                        raise Conflict(
                            f"hub id {self.hub.hub_id!r} is taken: {url} has {tid} registered by the "
                            f"live hub at {base}; give this hub another [hub] id (or remove its "
                            f"id file) - docs/scale-out.md")
        finally:
            client.close()

    async def _forget_stale(self) -> None:
        """Delete the TDs a previous run of this hub put and this one does not serve (a device
        removed from the config, a hub renamed): ids of this hub's (or the old, hub-less) scheme
        without a ttl. Other producers, other hubs sharing the database included, register with a
        ttl (``Registrar``) or another hub id, and are left alone."""
        served = {t.td.get("id") for t in self.hub.served()}
        directory = self.directory
        assert directory is not None
        stale = []
        offset = 0
        while True:
            page, total = directory.page(offset, 1000)
            for td in page:
                tid = td.get("id", "")
                if ((tid.startswith(self.hub.id_prefix) or tid.startswith(LEGACY_PREFIXES))
                        and tid not in served
                        and "expires" not in (td.get("registration") or {})):
                    stale.append(tid)
            offset += len(page)
            if not page or offset >= total:
                break
        for tid in stale:
            with contextlib.suppress(Exception):
                await directory.delete(tid)
        if stale:
            log.info("removed %d TD(s) of a previous run from the directory: %s", len(stale),
                     ", ".join(stale))

    def _add_registrar(self, url: str, token: str | None) -> None:
        from wott_directory import DirectoryClient, Registrar

        registrar = Registrar(DirectoryClient(url, token=token), ttl=self.cfg.ttl_s)
        self.registrars.append(registrar)
        worker = _Worker(url)
        worker.start()
        self._workers.append((worker, registrar))

    async def drain(self) -> None:
        """Wait until the directories have every change made so far (tests, orderly shutdown)."""
        for worker, _ in self._workers:
            await worker.drain()

    async def stop(self) -> None:
        """Stop writing; delete the hub's Things from the ``register_to`` directories (a clean stop:
        they are gone now, not in ttl seconds); close the embedded directory (its streams end)."""
        for worker, target in self._workers:  # the local one finishes; remote ones are unregistered
            await worker.stop(finish=target is self.directory)
        for registrar in self.registrars:
            try:  # a directory that does not answer must not hold the hub's shutdown up
                await asyncio.wait_for(registrar.stop(unregister=True), UNREGISTER_TIMEOUT_S)
            except Exception as e:  # TimeoutError included
                log.warning("could not unregister from %s (%s); the TDs expire in %g s", registrar.client.url,
                            type(e).__name__, self.cfg.ttl_s)
            registrar.client.close()
        if self.directory is not None:
            await self.directory.stop()
        self._workers.clear()
        self.registrars.clear()

    # --- the hub's Things -------------------------------------------------------------

    def exposed(self, td: dict[str, Any]) -> None:
        """The hub serves ``td`` (a new Thing, or a new TD of one): put it everywhere."""
        tid = td.get("id")
        if not isinstance(tid, str):
            return
        for worker, target in self._workers:
            worker.submit(self._put_op(target, tid, td))

    def removed(self, td: dict[str, Any]) -> None:
        tid = td.get("id")
        if not isinstance(tid, str):
            return
        for worker, target in self._workers:
            worker.submit(self._delete_op(target, tid))

    def _put_op(self, target: Any, tid: str, td: dict[str, Any]) -> Op:
        async def put() -> None:
            if self.directory is not None and target is self.directory:
                from wott_directory import DirectoryError

                try:
                    await target.put(tid, td)
                except DirectoryError as e:
                    details = "; ".join(f"{v.get('field')}: {v.get('description')}"
                                        for v in e.validation_errors)
                    log.error("the directory refused the TD of %s: %s %s", tid, e, details)
            else:
                await target.register(td)

        return put

    def _delete_op(self, target: Any, tid: str) -> Op:
        async def delete() -> None:
            if self.directory is not None and target is self.directory:
                if tid in target:
                    await target.delete(tid)
            else:
                await target.unregister(tid)

        return delete

    def describe(self) -> dict[str, Any]:
        return {"directory": self.url, "registered_to": [r.url for r in self.cfg.register_to]}
