"""The blocking API: the async core run on one event loop in a background thread.

As httpx pairs ``Client`` with ``AsyncClient``, each class here wraps its async
twin and hands coroutines to the client's loop. Streams cross the thread
boundary a batch at a time (one hand-off per network chunk, not per frame).
Leaving a ``for`` loop early closes the stream (the generator's ``close``).
"""

from __future__ import annotations

import asyncio
import os
import threading
from collections.abc import AsyncGenerator, Coroutine, Iterator, Sequence
from contextlib import aclosing
from types import TracebackType
from typing import Any, TypeVar

import numpy as np

from ._client import AsyncClient
from ._directory import AsyncDirectory
from ._fields import Displacement
from ._frames import Item
from ._history import AsyncHistory, FieldRange, Time
from ._td import Mesh
from ._thing import AsyncThing

__all__ = ["Client", "Directory", "History", "Thing"]

T = TypeVar("T")


class _Loop:
    """An event loop running in a daemon thread."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name="wott-client", daemon=True)
        self.thread.start()

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result()

    def iterate(self, agen: AsyncGenerator[list[T], None]) -> Iterator[T]:
        try:
            while True:
                try:
                    batch = self.run(agen.__anext__())
                except StopAsyncIteration:
                    return
                yield from batch
        finally:
            if self.loop.is_running():
                self.run(agen.aclose())

    def stop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


class Thing:
    """Blocking twin of ``AsyncThing``."""

    def __init__(self, core: AsyncThing, loop: _Loop) -> None:
        self.aio = core
        self._loop = loop

    def __repr__(self) -> str:
        return f"<Thing {self.id!r}>"

    @property
    def id(self) -> str:
        return self.aio.id

    @property
    def td(self) -> dict[str, Any]:
        return self.aio.td

    def mesh(self) -> Mesh:
        return self._loop.run(self.aio.async_mesh())

    def read_property(self, name: str) -> Any:
        return self._loop.run(self.aio.async_read_property(name))

    def frames(self, *, contacts: bool = True, actions: bool = True,
               last_event_id: str | None = None) -> Iterator[Item]:
        """Frames (and Contacts, Actions) as they come; break out of the loop to stop."""
        return self._loop.iterate(self.aio.async_batches(contacts=contacts, actions=actions,
                                                         last_event_id=last_event_id))

    def displacements(self, *, last_event_id: str | None = None) -> Iterator[Displacement]:
        """``skinDisplacement`` packets as they come (binary form when offered); break to stop."""
        return self._loop.iterate(self.aio.async_displacement_batches(last_event_id=last_event_id))

    @property
    def cameras(self) -> list[str]:
        return self.aio.cameras

    def image(self, camera: str | None = None) -> np.ndarray:
        """The camera's latest image, H x W x C uint8."""
        return self._loop.run(self.aio.async_image(camera))

    def pressure(self) -> np.ndarray:
        """The latest pressure grid, rows x cols float32 kPa."""
        return self._loop.run(self.aio.async_pressure())

    def frame(self, camera: str | None = None) -> np.ndarray:
        """The latest raw frame (a camera's image, else a pressure grid): digit-interface's ``get_frame``."""
        return self._loop.run(self.aio.async_frame(camera))

    def invoke(self, name: str, value: Any = None) -> Any:
        return self._loop.run(self.aio.async_invoke(name, value))

    def tare(self) -> Any:
        return self._loop.run(self.aio.async_tare())

    def restart(self) -> Any:
        return self._loop.run(self.aio.async_restart())

    def recalibrate(self) -> Any:
        return self._loop.run(self.aio.async_recalibrate())

    def observe(self, name: str, *, last_event_id: str | None = None) -> Iterator[Any]:
        """Values of observable property ``name`` as they change; break to stop."""
        agen = self.aio.async_observe(name, last_event_id=last_event_id)

        async def batches() -> AsyncGenerator[list[Any], None]:
            async with aclosing(agen):
                async for value in agen:
                    yield [value]

        return self._loop.iterate(batches())


class Directory:
    """Blocking twin of ``AsyncDirectory``."""

    def __init__(self, core: AsyncDirectory, loop: _Loop) -> None:
        self.aio = core
        self._loop = loop

    def tds(self) -> list[dict[str, Any]]:
        return self._loop.run(self.aio.async_tds())

    def search(self, jsonpath: str) -> list[Any]:
        return self._loop.run(self.aio.async_search(jsonpath))

    def things(self) -> list[Thing]:
        return [Thing(t, self._loop) for t in self._loop.run(self.aio.async_things())]

    def follow(self, *, contacts: bool = True, actions: bool = True) -> Iterator[tuple[Thing, Item]]:
        """Every Tactile Thing's items as ``(thing, item)``."""
        wrapped: dict[int, Thing] = {}

        async def batches() -> AsyncGenerator[list[tuple[Thing, Item]], None]:
            async for core, batch in self.aio.async_follow_batches(contacts=contacts, actions=actions):
                thing = wrapped.get(id(core)) or wrapped.setdefault(id(core), Thing(core, self._loop))
                yield [(thing, item) for item in batch]

        return self._loop.iterate(batches())


class History:
    """Blocking twin of ``AsyncHistory``."""

    def __init__(self, core: AsyncHistory, loop: _Loop) -> None:
        self.aio = core
        self._loop = loop

    def devices(self) -> list[dict[str, Any]]:
        return self._loop.run(self.aio.async_devices())

    def records(self, device: str, *, t_from: Time = None, t_to: Time = None,
                names: Sequence[str] | None = None, limit: int | None = None) -> Iterator[dict[str, Any]]:
        """The device's records in order; break out of the loop to stop early."""
        records = self.aio.async_records(device, t_from=t_from, t_to=t_to, names=names, limit=limit)

        async def batches() -> AsyncGenerator[list[dict[str, Any]], None]:
            buf: list[dict[str, Any]] = []
            async with aclosing(records):
                async for rec in records:
                    buf.append(rec)
                    if len(buf) >= 1000:
                        yield buf
                        buf = []
            if buf:
                yield buf

        return self._loop.iterate(batches())

    def range(self, device: str, name: str = "skinDisplacement", *, t_from: Time = None, t_to: Time = None,
              after: int = 0, limit: int | None = None) -> FieldRange:
        """The device's skin packets of the range as arrays (``AsyncHistory.async_range``)."""
        return self._loop.run(self.aio.async_range(device, name, t_from=t_from, t_to=t_to, after=after,
                                                   limit=limit))

    def start_episode(self, task: str) -> dict[str, Any]:
        """Start an episode of the recording (``AsyncHistory.async_start_episode``)."""
        return self._loop.run(self.aio.async_start_episode(task))

    def end_episode(self) -> dict[str, Any]:
        """End the open episode (``AsyncHistory.async_end_episode``)."""
        return self._loop.run(self.aio.async_end_episode())

    def export_mcap(self, path: str | os.PathLike[str], devices: Sequence[str] | str, *, t_from: Time = None,
                    t_to: Time = None, names: Sequence[str] | None = None, scene: bool = True,
                    scene_hz: float = 30.0) -> int:
        return self._loop.run(self.aio.async_export_mcap(path, devices, t_from=t_from, t_to=t_to, names=names,
                                                         scene=scene, scene_hz=scene_hz))


class Client:
    """``with Client() as c: for frame in c.thing(url).frames(): ...``"""

    def __init__(self, *, timeout_s: float = 10.0, mdns_interfaces: list[str] | None = None,
                 token: str | None = None) -> None:
        self._loop = _Loop()

        async def make() -> AsyncClient:
            return AsyncClient(timeout_s=timeout_s, mdns_interfaces=mdns_interfaces, token=token)

        self.aio = self._loop.run(make())

    def __enter__(self) -> Client:
        return self

    def __exit__(self, et: type[BaseException] | None, e: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        if self._loop.thread.is_alive():
            self._loop.run(self.aio.async_close())
            self._loop.stop()

    def thing(self, target: str) -> Thing:
        """The Tactile Thing at a TD URL or mDNS name."""
        return Thing(self._loop.run(self.aio.async_thing(target)), self._loop)

    def thing_from_td(self, td: dict[str, Any], url: str | None = None) -> Thing:
        return Thing(self.aio.thing_from_td(td, url), self._loop)

    def history(self, target: str) -> History:
        """A wott-hub's recorded history, from its hub Thing's TD URL."""
        return History(self._loop.run(self.aio.async_history(target)), self._loop)

    def directory(self, target: str, page_size: int | None = None) -> Directory:
        """A Thing Description Directory by its base URL or mDNS name."""
        return Directory(self._loop.run(self.aio.async_directory(target, page_size)), self._loop)
