"""One device's pipeline: its driver's frames through its processor into records for a sink.

The hub and its worker processes run this same object and make the same
records from a frame; they differ only in the sink a record goes to (the event
plane in the hub, a pipe to the hub in a worker, ``outbox.PipeSink``) and in
who wants it (the plane knows; a worker cannot, so its sink wants them all).
A record is made once, as a ``Record`` not yet numbered, and handed to the sink
(``types.RecordSink.put``): the plane numbers it, a pipe carries it as it is.

A ``DevicePipeline`` owns what changes as frames flow: the contact state (the
last contacts, encoded only when someone reads them) and the counters the hub
reports (``state``, ``reason``, ``frames``, ``frame_errors``, ``restarts``).
Others read those; only the pipeline changes them, through its transitions
(``started``, ``ended``, ``failed``, ``restarting``, ``retrying``, ``reopened``,
``remote_health``), so the states a device can be in are written in one place.
For a device running in a worker process, the hub keeps a pipeline without a
processor: its driver is the worker's proxy (``handle.DeviceHandle``) and its
contact state and counters are fed by the worker's messages (``remote_records``,
``remote_health``).

Every call into the driver (plugin code: ``frames``, ``health``, ``tare``,
``recalibrate``, ``close``; opening is ``opening.open_driver``) goes through the
pipeline's ``wott_hub.plugins.isolation.Guard``: whatever it raises marks this
device only (``state``/``reason``, or ``degraded`` with ``"health() raised ..."``),
is logged once with its traceback, and never reaches the hub Thing, the routes
or a watcher.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from wott_hub.drivers.base import (
    Driver,
    Health,
    HealthStatus,
    NoisyAtRest,
    RawSample,
    RawSignal,
    Recalibratable,
    ReportsUnavailableNodes,
    ServesRawSignals,
    Tareable,
)
from wott_hub.errors import Conflict, DriverError, NotFound
from wott_hub.events.fields import SKIN_DISPLACEMENT, FieldRecord
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, SkinArrays, encode
from wott_hub.plugins.isolation import CAUGHT, Guard
from wott_hub.tactile import FrameError, FrameProcessor, FrameResult
from wott_hub.types import FrameSink

from .opening import CLOSE_TIMEOUT_S, restart_backoff
from .payloads import contacts_json, displacement_rows, skin_deformed_json

if TYPE_CHECKING:
    from wott_hub.tactile import DeviceDescription
    from wott_hub.types import RecordSink

    from .handle import DeviceHandle

__all__ = ["ACTION", "CONTACTS", "NO_CONTACTS", "NO_UNAVAILABLE", "RESTARTED", "SKIN_DEFORMED",
           "SKIN_DISPLACEMENT", "UNAVAILABLE", "UNKNOWN_CONTACTS", "DevicePipeline", "Report",
           "initial_contacts", "tune_processor"]

log = logging.getLogger("wott_hub.hub")

SKIN_DEFORMED = "skinDeformedDetection"
ACTION = "actionDetection"
ACTION_DETAILS = "actionDetails"  # its sibling: confidence and evidence (issue 14)
CONTACTS = "contactInformation"
UNAVAILABLE = "unavailableNodes"  # a vision skin's nodes of unknown value (issue 14); always empty elsewhere

NO_CONTACTS = encode({"numOfContacts": 0, "contactLocations": [], "contactForces": []})
"""The contacts property before any frame: nothing touches the skin."""

UNKNOWN_CONTACTS = "null"
"""The contacts property of a device that measures its contacts (``measures_contacts``) before its first
frame with a reference: unknown, not "no contact" (issue 44)."""

NO_UNAVAILABLE = encode({"numOfUnavailableNodes": 0, "arrayOfUnavailableNodes": []})
"""The unavailable-nodes property of a skin that reads every node (and of any before its rest frame)."""

RESTARTING = "restarting on request"
"""The reason a device shows while a ``restart`` closes its driver and opens it again."""

RESTARTED = "driver closed and opened again; the stream continues"
"""A ``restart``'s detail once the driver is open again (in the hub's process or a worker's)."""


class Report(NamedTuple):
    """A pipeline's state and counters, as a worker reports them to the hub (every second, and after
    a device action)."""

    state: str
    reason: str
    frames: int
    frame_errors: int
    restarts: int


def tune_processor(processor: FrameProcessor, driver: DeviceHandle) -> None:
    """The below-threshold note at the driver's noise floor, for a driver whose rest readings are noisy
    (``NoisyAtRest``: the camera skins)."""
    if isinstance(driver, NoisyAtRest):
        processor.set_below_threshold(float(driver.below_threshold_floor), float(driver.below_threshold_s))


def initial_contacts(desc: DeviceDescription) -> str:
    """The contacts property before the device's first frame: unknown for a device that measures its
    contacts (its first frame needs a rest reference), else no contact."""
    return UNKNOWN_CONTACTS if desc.measures_contacts else NO_CONTACTS


def _health_of(driver: DeviceHandle) -> tuple[str, str]:
    h = driver.health()
    if not isinstance(h, HealthStatus):
        raise TypeError(f"returned a {type(h).__name__}, not a HealthStatus")
    return Health(h.state).value, str(h.reason)


class DevicePipeline:
    """Frames in, records out, for one device (its Thing id ``thing``)."""

    __slots__ = ("_reporter", "_unavailable", "contacts", "contacts_json", "driver", "frame_errors", "frames",
                 "guard", "had_contacts", "processor", "reason", "restarts", "state", "thing",
                 "unavailable_json")

    def __init__(self, thing: str, driver: DeviceHandle, processor: FrameProcessor | None,
                 contacts_json: str | None = NO_CONTACTS) -> None:
        self.thing = thing
        self.driver = driver  # a Driver; in the hub, a worker's proxy when processor is None
        self.processor = processor  # None: the device's frames are processed in a worker process
        self.state = "starting"  # starting | running | ended | failed | unplugged (else the driver's health)
        self.reason = ""
        self.frames = 0
        self.frame_errors = 0
        self.restarts = 0
        self.had_contacts = False
        self.contacts: FrameResult | None = None  # the last frame's contacts, encoded only when read
        self.contacts_json = contacts_json  # None until then
        self.guard = Guard(f"device {thing}", logger=log)  # every call into the driver (plugin code)
        self.unavailable_json = NO_UNAVAILABLE  # the ``unavailableNodes`` property's JSON
        self._unavailable: list[int] | None = None  # the driver's ``unavailable_nodes`` object last seen
        self._reporter: ReportsUnavailableNodes | None = None  # the driver, if it reports unavailable nodes
        if processor is not None:
            self._tune(driver, processor)

    @classmethod
    def of_driver(cls, thing: str, driver: Driver) -> DevicePipeline:
        """The pipeline of a driver opened in this process, with a processor made for its description."""
        return cls(thing, driver, _processor_for(driver), initial_contacts(driver.description))

    def _tune(self, driver: DeviceHandle, processor: FrameProcessor) -> None:
        tune_processor(processor, driver)
        self._reporter = driver if isinstance(driver, ReportsUnavailableNodes) else None

    # --- what the hub reports ------------------------------------------------------------

    def read_contacts(self) -> str:
        """The ``contactInformation`` property's JSON (encoded here when no record needed it)."""
        if self.contacts_json is None:
            contacts = self.contacts
            assert contacts is not None  # contacts_json is None only once a frame has set contacts
            self.contacts_json = contacts_json(contacts)
        return self.contacts_json

    def read_unavailable(self) -> str:
        """The ``unavailableNodes`` property's JSON."""
        return self.unavailable_json

    def _unavailable_changed(self, t_ns: int, sink: RecordSink) -> None:
        """Publish ``unavailableNodes`` when the driver's ``unavailable_nodes`` changed (vision skins). Per
        frame: an attribute read and an identity check; compared (and encoded) only when it is a new list."""
        reporter = self._reporter
        if reporter is None:
            return
        nodes = reporter.unavailable_nodes
        if nodes is self._unavailable:
            return
        previous, self._unavailable = self._unavailable, nodes
        if nodes == previous or (not nodes and not previous):
            return
        ids = [int(i) for i in nodes or ()]
        self.unavailable_json = encode({"numOfUnavailableNodes": len(ids), "arrayOfUnavailableNodes": ids})
        if sink.wants(self.thing, KIND_PROPERTY, UNAVAILABLE):
            sink.put(Record(self.thing, 0, KIND_PROPERTY, UNAVAILABLE, t_ns, self.unavailable_json))

    def health_state(self) -> tuple[str, str]:
        """(state, reason): the loop's own while starting and once it is over, else the driver's health.

        A ``health()`` that raises (or answers nonsense) makes the device
        ``degraded`` with the reason; it is logged when it starts, not on every read.
        """
        if self.state in ("ended", "failed", "starting", "unplugged"):  # unplugged: no driver (hub.usb)
            return "disconnected" if self.state == "unplugged" else self.state, self.reason
        out = self.guard.call("health()", _health_of, self.driver)
        if out.fault is not None:
            return "degraded", out.fault.reason
        state, reason = out.value  # type: ignore[misc]  # no fault: the value is set
        note = self.processor.below_note if self.processor is not None else ""
        if note and state in ("ok", "degraded") and "below threshold" not in reason:
            reason = f"{reason}; {note}" if reason else note  # a light press: the silence explained
        return state, reason

    def report(self) -> Report:
        """What a worker tells the hub each second."""
        state, reason = self.health_state()
        return Report(state, reason, self.frames, self.frame_errors, self.restarts)

    # --- device actions --------------------------------------------------------------------------

    def request(self, name: str) -> str:
        """Ask the driver to ``tare`` or ``recalibrate`` (carried out on its next frame): its sentence.

        Through the guard: a driver that raises fails this action only (``DriverError``).
        The same call in the hub's process and in a worker's.
        """
        driver = self.driver
        if name == "tare" and isinstance(driver, Tareable):
            fn = driver.tare
        elif name == "recalibrate" and isinstance(driver, Recalibratable):
            fn = driver.recalibrate
        else:  # declared only where the driver has it
            raise NotFound(f"device {self.thing!r} cannot {name}")
        out = self.guard.call(f"{name}()", fn)
        if out.fault is not None:
            raise DriverError(f"device {self.thing!r}: {out.fault.reason}")
        return str(out.value or name)

    # --- raw signals (``ServesRawSignals``), read on demand ------------------------------------------

    def raw_signals(self) -> tuple[RawSignal, ...]:
        """The driver's raw signals (none if it has no such capability, or if reading them fails: logged)."""
        driver = self.driver
        if not isinstance(driver, ServesRawSignals):
            return ()
        out = self.guard.call("raw_signals", _signals_of, driver)
        return out.value if out.fault is None and out.value is not None else ()

    def raw_sample(self, name: str) -> RawSample | None:
        """The driver's latest sample of signal ``name`` (None: none yet). Through the guard: a driver
        that raises, or answers something else than a ``RawSample``, fails this read only
        (``DriverError``)."""
        driver = self.driver
        if not isinstance(driver, ServesRawSignals):
            raise NotFound(f"device {self.thing!r} has no raw signals")
        out = self.guard.call(f"raw_sample({name!r})", _sample_of, driver, name)
        if out.fault is not None:
            raise DriverError(f"device {self.thing!r}: {out.fault.reason}")
        return out.value  # no fault: checked by _sample_of

    async def close(self) -> None:
        """Close the driver; a ``close()`` that raises or hangs is logged, never raised."""
        await self.guard.call_async("close()", self.driver.close, timeout_s=CLOSE_TIMEOUT_S)

    # --- its state: the transitions ---------------------------------------------------------------

    def started(self) -> None:
        """Its frames flow (here, or in the worker that was told to run it)."""
        self.state = "running"

    def ended(self, reason: str) -> None:
        """The driver's frame stream ended: the device is done."""
        self.state, self.reason = "ended", reason

    def unplugged(self, reason: str) -> None:
        """Its USB device is gone (``hub.usb``), its driver closed: health ``disconnected``, ``reason``."""
        self.state, self.reason = "unplugged", reason

    def failed(self, reason: str) -> None:
        """The device cannot run now (its driver did not open, its worker process exited...)."""
        self.state, self.reason = "failed", reason

    def restarting(self) -> None:
        """A ``restart`` is closing the driver and opening it again; counted where the driver runs (a
        worker's count reaches the hub in its reports)."""
        if self.processor is not None:
            self.restarts += 1
        self.state, self.reason = "starting", RESTARTING

    def retrying(self, reason: str, attempt: int, delay_s: float) -> None:
        """It failed to open for ``reason``; attempt ``attempt`` comes in ``delay_s``."""
        self.reason = f"{reason} (retry {attempt} in {delay_s:.1f} s)"

    def reopened(self, driver: Driver) -> None:
        """Carry on from a freshly opened ``driver`` (a ``restart``): a new processor, the same counters
        and contact state. Its mesh must be the served one (the TD stays true): else the device has
        failed and ``Conflict`` is raised, with ``driver`` kept to be closed (``close``)."""
        desc = driver.description
        served = self.processor.mesh.n_nodes if self.processor is not None else None
        self.driver = driver
        if desc.mesh.n_nodes != served:
            reason = (f"device {self.thing!r} reopened with {desc.mesh.n_nodes} nodes, not {served}: "
                      "remove it and add it again")
            self.failed(reason)
            raise Conflict(reason)
        self.processor = processor = _processor_for(driver)
        self._tune(driver, processor)
        self.state, self.reason = "starting", ""

    def remote_health(self, report: Report) -> None:
        """A worker's report of the pipeline it runs (``report`` there); the proxy mirrors the driver's
        health."""
        self.frames, self.frame_errors, self.restarts = report.frames, report.frame_errors, report.restarts
        if report.state in ("ended", "failed"):
            self.state, self.reason = report.state, report.reason
        else:
            self.state = "running"
            with contextlib.suppress(ValueError):  # not a Health: nothing to mirror
                self.driver.set_health(Health(report.state), report.reason)

    # --- frames to records -------------------------------------------------------------------

    def records(self, res: FrameResult, t_in: int, sink: RecordSink,
                displacement: np.ndarray | None = None) -> None:
        """Put the records of one frame that ``sink`` wants; unwanted ones are not even encoded.

        A skin packet when one is due (and its ``skinDisplacement`` sibling, the same nodes'
        vectors of the frame's ``displacement``, as numbers: its text and binary form are
        written by whoever reads them, ``events.fields``), one record per action, and the
        contacts property while touched and once more at rest. ``t_in``: trace stamps ride
        on the skin packet (0: not tracing).
        """
        thing = self.thing
        wants, put = sink.wants, sink.put
        trace = None
        if t_in:
            trace = {"in": t_in, "proc": time.perf_counter_ns()}
        t_ns = res.t_ns
        if res.packet_due and wants(thing, KIND_EVENT, SKIN_DEFORMED):
            data = skin_deformed_json(res)
            if trace is not None:
                trace["enc"] = time.perf_counter_ns()
            put(Record(thing, 0, KIND_EVENT, SKIN_DEFORMED, t_ns, data, trace,
                       SkinArrays(res.deformed_nodes, res.intensity)))
        if res.packet_due and displacement is not None and wants(thing, KIND_EVENT, SKIN_DISPLACEMENT):
            put(FieldRecord(thing, 0, t_ns, rows=displacement_rows(res, displacement)))
        if res.actions and wants(thing, KIND_EVENT, ACTION):
            for action in res.actions:
                put(Record(thing, 0, KIND_EVENT, ACTION, t_ns, encode(action)))
        if res.actions and wants(thing, KIND_EVENT, ACTION_DETAILS):
            for details in res.action_details():
                put(Record(thing, 0, KIND_EVENT, ACTION_DETAILS, t_ns, encode(details)))
        # the value changes while touched and once at rest; a measuring device's first frame ends "unknown"
        if res.contacts or self.had_contacts or (res.radii and self.contacts is None):
            self.had_contacts = bool(res.contacts)
            self.contacts = res
            if wants(thing, KIND_PROPERTY, CONTACTS):
                self.contacts_json = contacts_json(res)
                put(Record(thing, 0, KIND_PROPERTY, CONTACTS, t_ns, self.contacts_json))
            else:
                self.contacts_json = None

    async def run(self, sink: RecordSink, *, trace: bool = False) -> None:
        """Run the driver through the processor into ``sink`` until the stream ends.

        A frame the processor refuses is counted and skipped; a driver that raises
        is restarted with backoff (0.5 s doubling to 30 s), its failure logged once
        (``guard``) and shown as ``"frames() raised <Type>: <message>"``. ``trace``: stamp the
        skin packets (perf_counter ns). A ``types.FrameSink`` (a worker's pipe) is told
        after each frame's records.
        """
        driver, processor = self.driver, self.processor
        assert isinstance(driver, Driver) and processor is not None  # a worker's pipeline runs in the worker
        backoff = restart_backoff()
        clock = time.monotonic
        records, unavailable_changed = self.records, self._unavailable_changed
        frame_done = sink.frame_done if isinstance(sink, FrameSink) else None
        desc = driver.description  # skinDisplacement only in mm, and only from a skin that measures shear
        displaced = desc.node_signal.is_displacement and desc.shear
        while True:
            try:
                self.started()
                last_yield = clock()
                async for frame in driver.frames():
                    # A driver that is behind may yield frames without ever awaiting; then this
                    # loop would hold the event loop. Give the others a turn every 5 ms at most.
                    if clock() - last_yield > 0.005:
                        await asyncio.sleep(0)
                        last_yield = clock()
                    t_in = time.perf_counter_ns() if trace else 0
                    try:
                        res = processor.process(frame)
                    except FrameError as e:
                        self.frame_errors += 1
                        self.reason = str(e)
                        continue
                    self.frames += 1
                    records(res, t_in, sink, frame.displacement if displaced else None)
                    unavailable_changed(res.t_ns, sink)
                    if frame_done is not None:
                        frame_done()
                    if backoff.attempts:
                        backoff.reset()
                self.ended("the device's frame stream ended")
                return
            except asyncio.CancelledError:
                raise
            except CAUGHT as e:  # a driver bug (even a sys.exit()): report, back off, try again
                self.restarts += 1
                delay = backoff.next_delay()
                self.failed(self.guard.failed("frames()", e, retry_s=delay).reason)
                await asyncio.sleep(delay)

    # --- a pipeline that runs in a worker process, seen from the hub --------------------------

    def remote_records(self, recs: list[Record], sink: RecordSink) -> None:
        """One frame's records, made and encoded by the worker: keep the contacts, pass on the wanted."""
        thing, wants, put = self.thing, sink.wants, sink.put
        self.frames += 1
        for rec in recs:
            kind, name = rec.kind, rec.name
            if kind == KIND_PROPERTY and name == CONTACTS:
                self.contacts_json = rec.data
            elif kind == KIND_PROPERTY and name == UNAVAILABLE:
                self.unavailable_json = rec.data
            if wants(thing, kind, name):
                put(rec)


def _signals_of(driver: ServesRawSignals) -> tuple[RawSignal, ...]:
    signals = tuple(driver.raw_signals)
    if not all(isinstance(s, RawSignal) for s in signals):
        raise TypeError("raw_signals holds something else than RawSignal descriptions")
    if len({s.name for s in signals}) != len(signals):
        raise ValueError("raw_signals names a signal twice")
    return signals


def _sample_of(driver: ServesRawSignals, name: str) -> RawSample | None:
    sample = driver.raw_sample(name)
    if sample is None:
        return None
    if not (isinstance(sample, tuple) and len(sample) == 2 and isinstance(sample[1], np.ndarray)):
        raise TypeError(f"returned a {type(sample).__name__}, not a RawSample (t_ns, ndarray) or None")
    return RawSample(int(sample[0]), sample[1])


def _processor_for(driver: Driver) -> FrameProcessor:
    from wott_hub.tactile.processing import processing_params

    desc = driver.description
    return FrameProcessor(desc.mesh, processing_params(desc))
