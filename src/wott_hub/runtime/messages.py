"""What crosses the pipe between the hub and a worker process: one type per message.

Pickled by ``multiprocessing`` (named tuples: cheap to pickle, matched by type
on arrival). A device's records cross as ``Record``s not yet numbered (``seq``
0; ``Record.__reduce__`` sends a skin packet's arrays as raw bytes), the same
records the pipeline would put on the plane in the hub's process.

Order: a worker sends a device's records, and its ``Ended``, ``HealthReports``
or ``Acted`` after them, in the order they were made (``outbox.Outbox`` flushes
the waiting records before any other message).

Device actions: ``Act`` asks for one (``"tare"``, ``"recalibrate"``,
``"restart"``) with a ``request`` number the hub picks; the worker answers
``Acted`` with the same ``request``: ``detail`` (the driver's sentence) and
``error`` None, or ``error`` = (name of a ``wott_hub.errors`` class, message);
``report`` is the pipeline's right after, so the hub shows the effect at once.

Raw signals: ``Sample`` asks for the latest sample of a device's raw signal (a reader of its
image or grid, in the hub); the worker answers ``Sampled`` with the same ``request``: the
array as its dtype, shape and bytes (None before the first frame), or ``error`` as for ``Acted``.
The hub encodes it (``raw.RawSource``): the pipe carries only what a reader asked for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

from .pipeline import Report

if TYPE_CHECKING:
    from wott_hub.events.record import Record
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.tactile import DeviceDescription
    from wott_hub.tactile.raw import RawSignal

__all__ = ["Act", "Acted", "Batch", "Close", "CloseDevice", "Ended", "HealthReports", "Open", "OpenFailed",
           "Opened", "Run", "Sample", "Sampled", "ToHub", "ToWorker"]


# --- hub -> worker ---------------------------------------------------------------------------

class Open(NamedTuple):
    """Open this device (through the plugin registry) and answer ``Opened`` or ``OpenFailed``."""

    config: DeviceConfig


class Run(NamedTuple):
    """Start the device's pipeline (``trace``: stamp its skin packets)."""

    device: str
    trace: bool


class CloseDevice(NamedTuple):
    """Stop the device's pipeline (and any retry of it) and close its driver."""

    device: str


class Act(NamedTuple):
    """Do a device action; answered by ``Acted`` with the same ``request``."""

    device: str
    request: int
    action: str


class Sample(NamedTuple):
    """The latest sample of raw signal ``signal``; answered by ``Sampled`` with the same ``request``."""

    device: str
    request: int
    signal: str


class Close(NamedTuple):
    """Close every device and end the worker."""


ToWorker = Open | Run | CloseDevice | Act | Sample | Close


# --- worker -> hub ---------------------------------------------------------------------------

class Opened(NamedTuple):
    """The device is open: what the hub serves it as; ``capabilities``: the device actions its driver
    can do (``capabilities.driver_capabilities``, tested there)."""

    device: str
    description: DeviceDescription
    family: str
    capabilities: tuple[str, ...]
    raw_signals: tuple[RawSignal, ...] = ()  # its driver's (``ServesRawSignals``)


class OpenFailed(NamedTuple):
    """The device could not be opened (a ``DriverError``'s message, or why its processor refused it)."""

    device: str
    message: str


class Batch(NamedTuple):
    """The records of the frames made since the last batch, one list per frame, in the order made."""

    frames: list[list[Record]]


class HealthReports(NamedTuple):
    """Every device's pipeline report, each second."""

    reports: dict[str, Report]


class Ended(NamedTuple):
    """The device's frame stream ended."""

    device: str
    reason: str


class Acted(NamedTuple):
    """The answer to ``Act`` number ``request``."""

    request: int
    detail: str
    error: tuple[str, str] | None
    report: Report | None


class Sampled(NamedTuple):
    """The answer to ``Sample`` number ``request``: the array (``data`` None: no frame yet) or an error."""

    request: int
    t_ns: int
    dtype: str
    shape: tuple[int, ...]
    data: bytes | None
    error: tuple[str, str] | None


ToHub = Opened | OpenFailed | Batch | HealthReports | Ended | Acted | Sampled
