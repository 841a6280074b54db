"""One device's pipeline: its driver's frames through its processor into records for a sink.

The hub and its worker processes run this same object and make the same
records from a frame; they differ only in the sink a record goes to (the event
plane in the hub, a pipe to the hub in a worker, ``workers.PipeSink``) and in
who wants it (the plane knows; a worker cannot, so its sink wants them all).

A ``DevicePipeline`` owns what changes as frames flow: the contact state (the
last contacts, encoded only when someone reads them) and the counters the hub
reports (``state``, ``reason``, ``frames``, ``frame_errors``, ``restarts``).
For a device running in a worker process, the hub keeps a pipeline without a
processor: its driver is the worker proxy and its contact state and counters
are fed by the worker's messages (``remote_records``, ``remote_health``).

Every call into the driver (plugin code: ``open``/``prepare`` in ``open_driver``,
``frames``, ``health``, ``close``) goes through the pipeline's
``wott_hub.plugins.isolation.Guard``: whatever it raises marks this device only
(``state``/``reason``, or ``degraded`` with ``"health() raised ..."``), is logged
once with its traceback, and never reaches the hub Thing, the routes or a watcher.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import Driver, Health, HealthStatus, Recalibratable, Tareable
from wott_hub.errors import Conflict, DriverError, NotFound
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, SkinArrays, encode
from wott_hub.plugins.isolation import CAUGHT, Guard, attempt, attempt_async
from wott_hub.tactile import DeviceDescription, FrameError, FrameProcessor, FrameResult

from .payloads import contacts_json, skin_deformed_json

if TYPE_CHECKING:
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.plugins.registry import Registry

    from .workers import WorkerDevice

__all__ = ["ACTION", "CLOSE_TIMEOUT_S", "CONTACTS", "NO_CONTACTS", "NO_UNAVAILABLE", "SKIN_DEFORMED",
           "UNAVAILABLE", "DevicePipeline", "RecordSink", "driver_capabilities", "open_driver",
           "restart_backoff", "tune_processor"]

log = logging.getLogger("wott_hub.hub")

SKIN_DEFORMED = "skinDeformedDetection"
ACTION = "actionDetection"
ACTION_DETAILS = "actionDetails"  # its sibling: confidence and evidence (issue 14)
CONTACTS = "contactInformation"
UNAVAILABLE = "unavailableNodes"  # a vision skin's nodes of unknown value (issue 14); always empty elsewhere

NO_CONTACTS = encode({"numOfContacts": 0, "contactLocations": [], "contactForces": []})
"""The contacts property before any frame: nothing touches the skin."""

NO_UNAVAILABLE = encode({"numOfUnavailableNodes": 0, "arrayOfUnavailableNodes": []})
"""The unavailable-nodes property of a skin that reads every node (and of any before its rest frame)."""

CLOSE_TIMEOUT_S = 5.0
"""A driver's ``close()`` that has not returned by then is abandoned and reported: a stop waits no longer."""


def restart_backoff() -> Backoff:
    """The pacing of every retry of a device: a driver that raises, one that fails to open (at start or
    on a restart, ``hub.device_actions``): 0.5 s doubling to 30 s."""
    return Backoff(initial_s=0.5, cap_s=30.0, jitter=0.0)


def driver_capabilities(driver: Driver | WorkerDevice) -> tuple[str, ...]:
    """The device actions ``driver``'s capabilities give it (``tare``, ``recalibrate``): tested here, where
    the driver is, and reported by a worker process when it opens a device, so the hub declares the same
    actions for a device whatever process it runs in."""
    names = []
    if isinstance(driver, Tareable):
        names.append("tare")
    if isinstance(driver, Recalibratable):
        names.append("recalibrate")
    return tuple(names)


Wants = Callable[[str, int, str], bool]
Publish = Callable[[str, int, str, int, str, "dict[str, int] | None", "SkinArrays | None"], Any]


class RecordSink(Protocol):
    """Where a pipeline's records go: ``EventPlane`` in the hub, ``workers.PipeSink`` in a worker."""

    def wants(self, thing: str, kind: int, name: str) -> bool:
        """Is the record needed at all? If not, it is not even encoded."""
        ...

    def publish(self, thing: str, kind: int, name: str, t_ns: int, data: str,
                trace: dict[str, int] | None = None, skin: SkinArrays | None = None) -> Any:
        ...


async def open_driver(cfg: DeviceConfig, registry: Registry | None = None) -> Driver:
    """Open and prepare the device ``cfg`` (a ``DeviceConfig``) through its plugin, here or in a worker.

    Any failure is a ``DriverError`` naming the device: the plugin's own
    ``DriverError`` as it is, a bug as ``"<what> raised <Type>: <message>"``
    (logged once with its traceback). A driver that fails after opening is closed.
    """
    if registry is None:
        from wott_hub.plugins import get_registry

        registry = get_registry()
    driver: Driver = registry.open_device(cfg)  # the registry isolates the hook call (isolation.py)
    fault = (await attempt_async("prepare()", driver.prepare)).fault
    if fault is None:
        fault = attempt("description", _description_of, driver).fault
    if fault is None:
        return driver
    error = fault.error
    await attempt_async("close()", driver.close, timeout_s=CLOSE_TIMEOUT_S)
    if isinstance(error, DriverError):
        raise error
    log.error("device %s: %s", cfg.id, fault.reason, exc_info=(type(error), error, error.__traceback__))
    raise DriverError(f"device {cfg.id!r}: {fault.reason}") from error


def tune_processor(processor: FrameProcessor, driver: Any) -> None:
    """The below-threshold note at the driver's noise floor: a driver whose rest readings are noisy
    (the camera skins) declares ``below_threshold_floor`` (x ε) and ``below_threshold_s``."""
    floor = getattr(driver, "below_threshold_floor", None)
    if floor is not None:
        seconds = getattr(driver, "below_threshold_s", processor.params.below_threshold_s)
        processor.set_below_threshold(float(floor), float(seconds))


def _description_of(driver: Driver) -> DeviceDescription:
    desc = driver.description
    if not isinstance(desc, DeviceDescription):
        raise TypeError(f"is a {type(desc).__name__}, not a DeviceDescription")
    return desc


def _health_of(driver: Driver | WorkerDevice) -> tuple[str, str]:
    h = driver.health()
    if not isinstance(h, HealthStatus):
        raise TypeError(f"returned a {type(h).__name__}, not a HealthStatus")
    return Health(h.state).value, str(h.reason)


class DevicePipeline:
    """Frames in, records out, for one device (its Thing id ``thing``)."""

    __slots__ = ("_unavailable", "contacts", "contacts_json", "driver", "frame_errors", "frames", "guard",
                 "had_contacts", "processor", "reason", "restarts", "state", "thing", "unavailable_json")

    def __init__(self, thing: str, driver: Driver | WorkerDevice, processor: FrameProcessor | None,
                 contacts_json: str | None = NO_CONTACTS) -> None:
        self.thing = thing
        self.driver = driver  # a Driver; in the hub, a worker's proxy when processor is None
        self.processor = processor  # None: the device's frames are processed in a worker process
        self.state = "starting"  # starting | running | ended | failed (else the driver's health)
        self.reason = ""
        self.frames = 0
        self.frame_errors = 0
        self.restarts = 0
        self.had_contacts = False
        self.contacts: FrameResult | None = None  # the last frame's contacts, encoded only when read
        self.contacts_json = contacts_json  # None until then
        self.guard = Guard(f"device {thing}", logger=log)  # every call into the driver (plugin code)
        self.unavailable_json = NO_UNAVAILABLE  # the ``unavailableNodes`` property's JSON
        self._unavailable: Any = None  # the driver's ``unavailable_nodes`` object last seen
        if processor is not None:
            tune_processor(processor, driver)

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

    def _unavailable_changed(self, t_ns: int, wants: Wants, publish: Publish) -> None:
        """Publish ``unavailableNodes`` when the driver's ``unavailable_nodes`` changed (vision skins).

        Per frame: one attribute read and an identity check; the list is compared
        (and encoded) only when the driver made a new one.
        """
        nodes = getattr(self.driver, "unavailable_nodes", None)
        if nodes is self._unavailable:
            return
        previous, self._unavailable = self._unavailable, nodes
        if nodes == previous or (not nodes and not previous):
            return
        ids = [int(i) for i in nodes or ()]
        self.unavailable_json = encode({"numOfUnavailableNodes": len(ids), "arrayOfUnavailableNodes": ids})
        if wants(self.thing, KIND_PROPERTY, UNAVAILABLE):
            publish(self.thing, KIND_PROPERTY, UNAVAILABLE, t_ns, self.unavailable_json, None, None)

    def health_state(self) -> tuple[str, str]:
        """(state, reason): the loop's own while starting and once it is over, else the driver's health.

        A ``health()`` that raises (or answers nonsense) makes the device
        ``degraded`` with the reason; it is logged when it starts, not on every read.
        """
        if self.state in ("ended", "failed", "starting"):
            return self.state, self.reason
        out = self.guard.call("health()", _health_of, self.driver)
        if out.fault is not None:
            return "degraded", out.fault.reason
        state, reason = out.value  # type: ignore[misc]  # no fault: the value is set
        note = self.processor.below_note if self.processor is not None else ""
        if note and state in ("ok", "degraded") and "below threshold" not in reason:
            reason = f"{reason}; {note}" if reason else note  # a light press: the silence explained
        return state, reason

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

    def reopened(self, driver: Driver) -> None:
        """Carry on from a freshly opened ``driver`` (a ``restart``): a new processor, the same counters
        and contact state. Its mesh must be the served one (the TD stays true), else ``Conflict``."""
        from wott_hub.tactile.processing import processing_params

        desc = driver.description
        served = self.processor.mesh.n_nodes if self.processor is not None else None
        if desc.mesh.n_nodes != served:
            raise Conflict(f"device {self.thing!r} reopened with {desc.mesh.n_nodes} nodes, not {served}: "
                           "remove it and add it again")
        self.driver = driver
        self.processor = FrameProcessor(desc.mesh, processing_params(desc))
        tune_processor(self.processor, driver)
        self.state, self.reason = "starting", ""

    async def close(self) -> None:
        """Close the driver; a ``close()`` that raises or hangs is logged, never raised."""
        await self.guard.call_async("close()", self.driver.close, timeout_s=CLOSE_TIMEOUT_S)

    # --- frames to records -------------------------------------------------------------------

    def records(self, res: FrameResult, t_in: int, wants: Wants, publish: Publish) -> None:
        """Publish the records of one frame that someone wants; unwanted ones are not even encoded.

        A skin packet when one is due, one record per action, and the contacts
        property while touched and once more at rest. ``t_in``: trace stamps ride
        on the skin packet (0: not tracing). ``wants``/``publish``: a sink's, bound.
        """
        thing = self.thing
        trace = None
        if t_in:
            trace = {"in": t_in, "proc": time.perf_counter_ns()}
        t_ns = res.t_ns
        if res.packet_due and wants(thing, KIND_EVENT, SKIN_DEFORMED):
            data = skin_deformed_json(res)
            if trace is not None:
                trace["enc"] = time.perf_counter_ns()
            publish(thing, KIND_EVENT, SKIN_DEFORMED, t_ns, data, trace,
                    SkinArrays(res.deformed_nodes, res.intensity))
        if res.actions and wants(thing, KIND_EVENT, ACTION):
            for action in res.actions:
                publish(thing, KIND_EVENT, ACTION, t_ns, encode(action), None, None)
        if res.actions and wants(thing, KIND_EVENT, ACTION_DETAILS):
            for details in res.action_details():
                publish(thing, KIND_EVENT, ACTION_DETAILS, t_ns, encode(details), None, None)
        if res.contacts or self.had_contacts:  # the value changes while touched and once at rest
            self.had_contacts = bool(res.contacts)
            self.contacts = res
            if wants(thing, KIND_PROPERTY, CONTACTS):
                self.contacts_json = contacts_json(res)
                publish(thing, KIND_PROPERTY, CONTACTS, t_ns, self.contacts_json, None, None)
            else:
                self.contacts_json = None

    async def run(self, sink: RecordSink, *, trace: bool = False,
                  frame_done: Callable[[], None] | None = None) -> None:
        """Run the driver through the processor into ``sink`` until the stream ends.

        A frame the processor refuses is counted and skipped; a driver that raises
        is restarted with backoff (0.5 s doubling to 30 s), its failure logged once
        (``guard``) and shown as ``"frames() raised <Type>: <message>"``. ``trace``: stamp the
        skin packets (perf_counter ns). ``frame_done``: called after each frame's
        records (the pipe sink sends them as one message).
        """
        driver, processor = self.driver, self.processor
        assert isinstance(driver, Driver) and processor is not None  # a worker's pipeline runs in the worker
        backoff = restart_backoff()
        clock = time.monotonic
        wants, publish, records = sink.wants, sink.publish, self.records
        while True:
            try:
                self.state = "running"
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
                    records(res, t_in, wants, publish)
                    self._unavailable_changed(res.t_ns, wants, publish)
                    if frame_done is not None:
                        frame_done()
                    if backoff.attempts:
                        backoff.reset()
                self.state = "ended"
                self.reason = "the device's frame stream ended"
                return
            except asyncio.CancelledError:
                raise
            except CAUGHT as e:  # a driver bug (even a sys.exit()): report, back off, try again
                self.restarts += 1
                self.state = "failed"
                delay = backoff.next_delay()
                self.reason = self.guard.failed("frames()", e, retry_s=delay).reason
                await asyncio.sleep(delay)

    # --- a pipeline that runs in a worker process, seen from the hub --------------------------

    def remote_records(self, recs: list[tuple[Any, ...]], sink: RecordSink) -> None:
        """One frame's records, made and encoded by the worker (``(kind, name, t_ns, data, trace, skin)``):
        keep the contacts, pass on the wanted."""
        thing, wants, publish = self.thing, sink.wants, sink.publish
        self.frames += 1
        for kind, name, t_ns, data, trace, skin in recs:
            if kind == KIND_PROPERTY and name == CONTACTS:
                self.contacts_json = data
            elif kind == KIND_PROPERTY and name == UNAVAILABLE:
                self.unavailable_json = data
            if wants(thing, kind, name):
                publish(thing, kind, name, t_ns, data, trace, skin)

    def remote_health(self, state: str, reason: str, frames: int, frame_errors: int, restarts: int) -> None:
        """A worker's report of the pipeline it runs (``report`` there)."""
        self.frames, self.frame_errors, self.restarts = frames, frame_errors, restarts
        if state in ("ended", "failed"):
            self.state, self.reason = state, reason
        else:
            self.state = "running"
            driver = self.driver
            assert not isinstance(driver, Driver)  # a worker reports: the driver is its proxy
            driver.mirror(state, reason)

    def report(self) -> tuple[str, str, int, int, int]:
        """(state, reason, frames, frame_errors, restarts): what a worker tells the hub each second."""
        state, reason = self.health_state()
        return state, reason, self.frames, self.frame_errors, self.restarts
