"""Fleet management while the hub runs: the hub Thing's ``addDevice``, ``removeDevice`` and
``restartDevice`` actions, and the retrying of devices that failed to open at start.

Adding or removing a device touches that device only: its Thing is served or
unserved on its own (``Things.serve``/``unserve``), every other stream, its
sequence numbers and its subscribers carry on; the hub's network side (TD
directory, mDNS) hears of it through the servient's ``on_expose``/``on_remove``
like for any Thing. ``restartDevice`` is the device's own ``restart`` action
(device_actions.py).

A configured device that fails to open at start (``failed`` in health, with
its reason) is opened again with the restart backoff (0.5 s doubling to
30 s, ``runtime.opening.restart_backoff``) until it opens, and is then served
like the others (TD, directory, mDNS); its health reason says when the next
attempt is. A device whose configuration can never open (unknown family,
settings its family's schema refuses) is not retried: its reason says to fix
the configuration.

Errors of ``addDevice``: input that is not a device table, an unknown family or
bad settings → 400 naming the field (``InvalidInput``); an id already used → 409
(``Conflict``); a device that cannot be opened now → 422 (``DriverError``),
nothing kept. ``removeDevice``/``restartDevice`` of an unknown id → 404.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import TYPE_CHECKING, Any

from wott_hub.errors import Conflict, DriverError, InvalidInput, NotFound, WottHubError
from wott_hub.runtime.opening import restart_backoff
from wott_hub.runtime.tasks import TasksById
from wott_hub.servient import HUB_THING_ID

from .actions import install as install_actions

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.plugins.model import DeviceConfig

    from .device_actions import DeviceActions
    from .devices import Devices

__all__ = ["FLEET_ACTIONS", "FleetManagement"]

log = logging.getLogger("wott_hub.hub")

_ID = {"type": "string", "description": "The device's id (its Thing id on this hub)."}

FLEET_ACTIONS: dict[str, dict[str, Any]] = {
    "addDevice": {
        "title": "addDevice",
        "description": "Open a device and serve it, like a [[device]] table of the hub's configuration; "
                       "the other devices' streams are not interrupted.",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {
            "type": "object",
            "properties": {
                "id": _ID,
                "family": {"type": "string", "description": "Its device family (wott-hub plugins list)."},
                "settings": {"type": "object", "description": "The family's settings (the table's other "
                                                              "keys; they may also be given beside id)."},
            },
            "required": ["id", "family"],
        },
        "output": {
            "type": "object",
            "properties": {"id": {"type": "string"}, "td": {"type": "string", "format": "uri"},
                           "state": {"type": "string"},
                           "actions": {"type": "array", "items": {"type": "string"}}},
        },
    },
    "removeDevice": {
        "title": "removeDevice",
        "description": "Stop a device and stop serving it (its subscribers' streams end); the other devices' "
                       "streams are not interrupted.",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {"type": "object", "properties": {"id": _ID}, "required": ["id"]},
        "output": {"type": "object",
                   "properties": {"id": {"type": "string"}, "removed": {"type": "boolean"}}},
    },
    "restartDevice": {
        "title": "restartDevice",
        "description": "Close a device's driver and open it again (its 'restart' action); a device that "
                       "failed to open is tried again now. Its Thing, stream and sequence numbers are kept.",
        "safe": False,
        "idempotent": False,
        "synchronous": True,
        "input": {"type": "object", "properties": {"id": _ID}, "required": ["id"]},
        "output": {
            "type": "object",
            "properties": {"device": {"type": "string"}, "invokedAction": {"type": "string"},
                           "outcome": {"type": "string"}, "detail": {"type": "string"},
                           "timeStamp": {"type": "integer"}},
        },
    },
}


class FleetManagement:
    def __init__(self, config: HubConfig, devices: Devices, actions: DeviceActions) -> None:
        self.config = config
        self.devices = devices
        self.actions = actions
        self.configs: dict[str, DeviceConfig] = {d.id: d for d in config.devices}  # by id, for retries
        self.retrying = TasksById("retry")  # failed to open (not served): its retry loop

    # --- the actions ----------------------------------------------------------------------------

    async def add(self, table: Any) -> dict[str, Any]:
        """``addDevice``: check ``table`` (``{id, family, settings}`` or a flat TOML table), open, serve."""
        dcfg = _device_config(table)
        self._check_free(dcfg.id)
        from wott_hub.plugins import get_registry

        try:
            get_registry().validate(dcfg)  # unknown family, bad settings: the caller's mistake (400)
        except DriverError as e:
            raise InvalidInput(str(e)) from None
        try:
            dev = await self.devices.add_device(dcfg)
        except WottHubError:
            raise
        except Exception as e:  # a description the hub cannot serve (plugin data): that device only
            log.exception("device %s not added", dcfg.id)
            raise DriverError(f"device {dcfg.id!r}: {type(e).__name__}: {e}") from None
        self.configs[dcfg.id] = dcfg
        state, _ = dev.health_state()
        return {"id": dev.id, "td": self.devices.things.server.td_url(dev.id), "state": state,
                "actions": self.actions.declared(dev)}

    def _check_free(self, device_id: str) -> None:
        if device_id.casefold() == HUB_THING_ID:
            raise Conflict(f"'id': {device_id!r} is the hub's own Thing")
        served = self.devices.things.server.things.get(device_id)  # ids regardless of case (ThingRegistry)
        if served is not None:
            raise Conflict(f"'id': {device_id!r} is already served on this hub (as {served.id!r}: ids are "
                           "compared regardless of case)")
        if device_id.casefold() in {d.casefold() for d in self.devices.failed}:
            raise Conflict(f"'id': {device_id!r} is a configured device that failed to open "
                           "(remove it first)")

    async def remove(self, device_id: Any) -> dict[str, Any]:
        """``removeDevice``: stop retrying it, or stop and unserve it."""
        device_id = _id(device_id)
        served = self.devices.things.server.things.get(device_id)
        if served is not None:  # its id as served, whatever the case it was given in
            device_id = served.id
        self.retrying.cancel(device_id)
        if device_id in self.devices.running:
            self.actions.cancel_reopen(device_id)
            await self.devices.remove(device_id)
        elif self.devices.failed.pop(device_id, None) is None:
            raise NotFound(f"no device {device_id!r} on this hub")
        self.configs.pop(device_id, None)
        return {"id": device_id, "removed": True}

    async def restart(self, device_id: Any) -> dict[str, Any]:
        """``restartDevice``: the device's ``restart``; one that failed to open is tried now."""
        device_id = _id(device_id)
        dev = self.devices.running.get(device_id)
        if dev is not None:
            if dev.config is None:
                raise Conflict(f"device {device_id!r} cannot be reopened by the hub (it was added as an "
                               "open driver): remove it and add it again")
            return await self.actions.invoke(device_id, "restart")
        dcfg = self.configs.get(device_id)
        if device_id not in self.devices.failed or dcfg is None:
            raise NotFound(f"no device {device_id!r} on this hub")
        self.retrying.cancel(device_id)
        t_ns = time.time_ns()
        try:
            await self.devices.add_device(dcfg)
        except DriverError as e:
            self._retry(dcfg, str(e))
            raise
        self.devices.failed.pop(device_id, None)
        return {"device": device_id, "invokedAction": "restart", "outcome": "ok",
                "detail": "opened and served", "timeStamp": t_ns}

    # --- devices that failed to open at start ---------------------------------------------------

    def start(self) -> None:
        """Retry every configured device that failed to open (once the hub is up)."""
        from wott_hub.plugins import get_registry

        for device_id, reason in list(self.devices.failed.items()):
            dcfg = self.configs.get(device_id)
            if dcfg is None or device_id in self.retrying:
                continue
            try:
                get_registry().validate(dcfg)
            except DriverError:  # its configuration can never open: retrying would only repeat the error
                self.devices.failed[device_id] = f"{reason} (not retried: fix the configuration)"
                continue
            self._retry(dcfg, reason)

    def _retry(self, dcfg: DeviceConfig, reason: str) -> None:
        self.devices.failed[dcfg.id] = reason
        self.retrying.start(dcfg.id, self._retry_loop(dcfg, reason))

    async def _retry_loop(self, dcfg: DeviceConfig, reason: str) -> None:
        backoff = restart_backoff()
        while True:
            delay = backoff.next_delay()
            self.devices.failed[dcfg.id] = f"{reason} (retry {backoff.attempts} in {delay:.1f} s)"
            await asyncio.sleep(delay)
            try:
                await self.devices.add_device(dcfg)
            except Conflict as e:  # its id was taken meanwhile (an embedding program): give up
                self.devices.failed[dcfg.id] = str(e)
                return
            except DriverError as e:
                reason = str(e)
                continue
            except Exception as e:  # a description the hub cannot serve: keep trying, say why
                log.exception("device %s not started", dcfg.id)
                reason = f"device {dcfg.id!r}: {type(e).__name__}: {e}"
                continue
            self.devices.failed.pop(dcfg.id, None)
            log.info("device %s opened after %d attempt(s)", dcfg.id, backoff.attempts)
            return

    async def stop(self) -> None:
        await self.retrying.stop()
        await self.actions.stop()

    # --- HTTP -----------------------------------------------------------------------------------

    def install(self, td: dict[str, Any]) -> None:
        """Declare the fleet actions in the hub Thing's TD (before it is served) and mount their handlers,
        with the device actions' route."""
        server = self.devices.things.server
        server.add_handlers(self.actions.routes())
        invokes = {"addDevice": self.add, "removeDevice": lambda x: self.remove(x.get("id")),
                   "restartDevice": lambda x: self.restart(x.get("id"))}
        install_actions(td, server, {name: (aff, invokes[name]) for name, aff in FLEET_ACTIONS.items()})

def _id(value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise InvalidInput("'id': required, a device id (a non-empty string)")
    return value


def _device_config(table: Any) -> DeviceConfig:
    """A ``DeviceConfig`` from the action's input; ``InvalidInput`` naming the field at fault."""
    from wott_hub.plugins import DeviceConfig

    if not isinstance(table, dict):
        raise InvalidInput("the input must be an object: id, family and settings")
    flat = {k: v for k, v in table.items() if k not in ("id", "family", "settings")}
    settings = table.get("settings", {})
    if not isinstance(settings, dict):
        raise InvalidInput("'settings': must be an object (the family's settings)")
    if flat and "settings" in table:
        raise InvalidInput(f"{next(iter(flat))!r}: give the settings in 'settings' or beside 'id', not both")
    try:
        return DeviceConfig.from_table({**settings, **flat, "id": table.get("id"),
                                        "family": table.get("family")}, where="addDevice")
    except DriverError as e:  # "addDevice.id: required, a non-empty string"
        raise InvalidInput(str(e)) from None

