"""Device actions (``tare``, ``restart``, ``recalibrate``), invoked by any WoT client over HTTP.

Each device TD declares the actions its driver can do (``runtime.capabilities.action_names``,
from the capabilities in ``wott_hub.drivers.base``; ``wott_hub.td.actions`` has their
schemas); ``POST /wot/<device>/actions/<name>`` performs one. The hub Thing's
``restartDevice`` action (management.py) goes through ``DeviceActions.invoke`` too.

Contract of ``restart`` (``wott_hub.runtime.restart``, the same in a worker process):
the served Thing is kept, and with it its event stream, its sequence numbers and every
subscriber; only the driver is closed and opened again through the plugin registry (from
the ``DeviceConfig`` it was opened from), with a new ``FrameProcessor``. If the new open
fails, the device stays served as ``failed`` with the reason and is retried with the
restart backoff until it opens, is removed or the hub stops.

Every invocation is recorded: a ``deviceAction`` event on the device's own stream
(history keeps it with the device's records, subscribers see it in order with
the frames it affects) and counters in the device's health (``tares``,
``lastTare``, ``recalibrations``, ``lastRecalibration``, ``lastRestart``; a
restart also counts in ``restarts``). Calls into the driver go through its
pipeline's guard: a plugin that raises fails that action (422), nothing else.

A device in a worker process (``[hub] workers``) declares the same actions: its
worker reports its driver's capabilities when it opens it, and the hub sends
each invocation over the pipe and awaits the answer (``runtime.pool`` has the
timeouts, ``runtime.worker`` the actions done there); recording, counters and
errors are the in-process ones, here.
"""

from __future__ import annotations

import re
import time
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict, NotFound, WottHubError
from wott_hub.events.record import KIND_EVENT, encode
from wott_hub.runtime.restart import Restarts
from wott_hub.servient import HUB_THING_ID

from .actions import ActionHandler

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane

    from .devices import DeviceRuntime, Devices

__all__ = ["DEVICE_ACTION", "DeviceActions"]

DEVICE_ACTION = "deviceAction"
"""The event each invocation publishes on the device's stream (declared in every device TD)."""


def _iso(t_ns: int) -> str:
    return datetime.fromtimestamp(t_ns / 1e9, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


class DeviceActions:
    """Performs device actions on the hub's running devices and keeps their re-open retries."""

    def __init__(self, devices: Devices, plane: EventPlane) -> None:
        self.devices = devices
        self.plane = plane
        self.restarts = Restarts(devices)  # restarts of devices in this process, and their retries

    def declared(self, dev: DeviceRuntime) -> list[str]:
        return list((dev.thing.td.get("actions") or {}).keys())

    def device(self, device_id: str) -> DeviceRuntime:
        dev = self.devices.running.get(device_id)
        if dev is None:
            raise NotFound(f"no device {device_id!r} on this hub")
        return dev

    async def invoke(self, device_id: str, name: str) -> dict[str, Any]:
        """Do action ``name`` on ``device_id``: its outcome, also published as a ``deviceAction`` event.

        ``NotFound`` for an unknown device or an action it does not declare;
        ``Conflict`` for a restart already under way; ``DriverError`` when the
        driver fails the action (the event says so too).
        """
        dev = self.device(device_id)
        if name not in self.declared(dev):
            declared = ", ".join(self.declared(dev)) or "none"
            raise NotFound(f"device {device_id!r} has no action {name!r} (its actions: {declared})")
        t_ns = time.time_ns()
        try:
            if name == "restart":
                detail = await self.restart(dev)
            else:
                detail = await self._capability(dev, name)
        except WottHubError as e:
            self._record(dev, name, t_ns, "failed", str(e))
            raise
        return self._record(dev, name, t_ns, "ok", detail)

    async def _capability(self, dev: DeviceRuntime, name: str) -> str:
        """``tare`` or ``recalibrate``: a request to the driver (here or in its worker), carried out on its
        next frame."""
        if dev.worker is not None:
            detail = await self._remote(dev, name)
        else:
            detail = dev.pipeline.request(name)
        key = "tares" if name == "tare" else "recalibrations"
        dev.actions[key] = dev.actions.get(key, 0) + 1
        return detail

    async def _remote(self, dev: DeviceRuntime, name: str) -> str:
        """``name`` done by ``dev``'s worker process: its health as the worker reports it right after,
        and its detail, or the error it answered (a ``WottHubError`` of the same class)."""
        assert dev.worker is not None
        detail, error, report = await dev.worker.act(name)
        if report is not None and self.devices.running.get(dev.id) is dev:
            dev.pipeline.remote_health(report)
        if error is not None:
            raise error
        return detail

    def _record(self, dev: DeviceRuntime, name: str, t_ns: int, outcome: str, detail: str) -> dict[str, Any]:
        out = {"device": dev.id, "invokedAction": name, "outcome": outcome, "detail": detail,
               "timeStamp": t_ns}
        last = {"tare": "lastTare", "recalibrate": "lastRecalibration", "restart": "lastRestart"}[name]
        dev.actions[last] = _iso(t_ns)
        dev.actions["lastAction"] = {"action": name, "outcome": outcome, "detail": detail, "at": _iso(t_ns)}
        if dev.id in self.plane.streams:  # still served (a restart may end with a removal)
            self.plane.publish(dev.id, KIND_EVENT, DEVICE_ACTION, t_ns, encode(out))
        return out

    # --- restart ------------------------------------------------------------------------------

    async def restart(self, dev: DeviceRuntime) -> str:
        """Close the driver and open it again; the Thing, its stream and its sequence stay."""
        if dev.config is None:
            raise Conflict(f"device {dev.id!r} cannot be reopened by the hub")
        if dev.worker is None:
            return await self.restarts.restart(dev.id, dev.pipeline, dev.config)
        with self.restarts.one_at_a_time(dev.id):  # its worker closes, opens and retries it
            dev.pipeline.restarting()
            return await self._remote(dev, "restart")

    def cancel_reopen(self, device_id: str) -> None:
        self.restarts.cancel(device_id)

    async def stop(self) -> None:
        await self.restarts.stop()

    # --- HTTP -----------------------------------------------------------------------------------

    def routes(self) -> list[tuple[Any, ...]]:
        """``POST /wot/<device>/actions/<name>`` (not the hub Thing's: management.py and replay.py)."""
        hub = re.escape(HUB_THING_ID)

        async def invoke(_input: dict[str, Any], thing_id: str, name: str) -> dict[str, Any]:
            return await self.invoke(thing_id, name)  # the actions take no input

        return [(rf"/wot/(?!{hub}/)(?P<thing_id>[^/]+)/actions/(?P<name>[^/]+)", ActionHandler,
                 {"invoke": invoke})]
