"""The seams one part of the hub hands another, named once (like starlette's ``types.py``).

Where a part is given something to call rather than an object to use, the
contract is written here and nowhere else: a module that takes or supplies one
imports its name from this module, so a reader finds every such seam, with
its arguments and meaning, in one place. Small protocols where the seam has
more than one operation (a record sink), aliases where it is one call.

A vocabulary, not a part: it sits in the layer of ``events`` (the record it
speaks of, imported for annotations only) and imports nothing of the hub at
run time, so every layer from ``events`` down may use it, the event plane's own
modules included (tests/test_architecture.py).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:  # annotations only: importing the events package here would be a cycle through it
    from wott_hub.events.record import Record
    from wott_hub.tactile.raw import RawSignal

__all__ = ["Direct", "Emit", "Encoded", "FormFactory", "FrameSink", "Invoke", "RawReads", "RecordSink"]


class RecordSink(Protocol):
    """Where a device pipeline's records go (``runtime.pipeline``): the event plane in the hub's
    process (``events.plane.EventPlane``), a pipe to the hub in a worker's (``runtime.outbox.PipeSink``).

    A pipeline asks ``wants`` before it builds a record, so a record nobody needs is
    never encoded; it then hands over the record, not yet numbered (``seq`` 0): the
    plane numbers it, a pipe carries it as it is. The sink keeps the record (rings,
    subscribers, history): the caller must not change it afterwards.
    """

    def wants(self, thing: str, kind: int, name: str) -> bool:
        """Is a record of ``thing``'s affordance (``kind``, ``name``) needed at all?"""
        ...

    def put(self, rec: Record) -> None:
        """Take ``rec``, one of the records ``wants`` said yes to."""
        ...


@runtime_checkable
class FrameSink(RecordSink, Protocol):
    """A record sink that sends a frame's records together (a worker's pipe): the pipeline says when
    the records of a frame are all in."""

    def frame_done(self) -> None:
        """The records ``put`` since the last call are one frame's."""
        ...


class Encoded(Protocol):
    """One encoding of a raw sample (``runtime.raw.Encoded``): its frame time, bytes, media type."""

    @property
    def t_ns(self) -> int: ...

    @property
    def body(self) -> bytes: ...

    @property
    def content_type(self) -> str: ...


class RawReads(Protocol):
    """A device's raw signals as the servient serves them (``runtime.raw.RawSource``): read on demand,
    encoded once per frame and format whatever the number of readers."""

    @property
    def signals(self) -> tuple[RawSignal, ...]:
        """The device's raw signals (``tactile.raw.RawSignal``)."""
        ...

    async def read(self, name: str, fmt: str) -> Encoded | None:
        """Signal ``name``'s latest sample in format ``fmt`` (``json``, ``png``, ``jpeg``, ``npy``), None
        before its first frame; ``DriverError`` if the device fails to give one."""
        ...


Direct = Callable[["Record"], bool]
"""A consumer's writer of one record (``events.subscriber.Subscriber.push``): True if written at
once, False to queue it."""

FormFactory = Callable[[str, str, dict[str, Any]], list[dict[str, Any]]]
"""The forms of one affordance in a TD (``td.forms.FormLayout.factory``): (kind ``"property"`` |
``"event"`` | ``"action"``, affordance name, affordance) -> forms."""

Invoke = Callable[..., Awaitable[Any]]
"""An action served over HTTP (``hub.actions``): ``invoke(input, **route_groups)``, the action's output
or a ``Stream``."""

Emit = Callable[["Record"], None]
"""A replay's output (``history.replay.Replayer.run``): ``emit(record)``, a record made for this
emission: its Thing, seq, affordance and payload as recorded, its ``t_ns`` the time it is emitted."""
