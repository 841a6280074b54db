"""The hub Thing: what the hub serves and how it is doing, as WoT properties and events.

Its properties ``devices``, ``health`` and ``eventCounters`` are computed when
read; a watcher publishes ``healthChange`` when a device's state changes, and the
``health`` property (when someone observes it: an SSE client, the MQTT publisher,
which retains it) at its first pass and whenever the hub's own state, history's,
the broker link's or a device's changes: an observer's last value is never stale. Nothing a plugin
does can break them: a device's ``health()`` is read through its pipeline's
guard (``runtime.pipeline``), and a watcher iteration that fails anyway is logged (once
per distinct failure) and the watcher carries on. ``health`` names the plugins
that failed to load (``plugins.failed``), without degrading the hub for them. Its ``replay`` and
``stopReplay`` actions are declared and mounted by ``replay.Replays.install``.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, encode
from wott_hub.plugins.isolation import Guard
from wott_hub.plugins.registry import loaded_registry
from wott_hub.servient import HUB_THING_ID, ServedThing

if TYPE_CHECKING:
    from wott_hub.events.plane import EventPlane
    from wott_hub.mqtt.publisher import MqttPublisher

    from .devices import Devices
    from .recording import HubHistory
    from .replay import Replays
    from .things import Things

__all__ = ["HubStatus"]

log = logging.getLogger("wott_hub.hub")


class HubStatus:
    def __init__(self, plane: EventPlane, devices: Devices, replays: Replays, history: HubHistory,
                 hub_state: Callable[[], str]) -> None:
        self.plane = plane
        self.devices = devices
        self.replays = replays
        self.history = history
        self.hub_state = hub_state  # starting | ok | stopping | stopped
        self.started_at = 0.0
        self.mqtt: MqttPublisher | None = None  # set by [mqtt]: the broker link's health is the hub's
        self.foxglove: Any = None  # set by [foxglove]: its clients and what it sent (robotics/live.py)
        self._task: asyncio.Task[None] | None = None

    def expose(self, things: Things, td: dict[str, Any]) -> None:
        """Serve the hub Thing (``td``: ``servient.hub_td``, with the replay actions declared)."""
        things.serve(ServedThing.create(HUB_THING_ID, td, record=False, dynamic={
            "devices": lambda: encode(self.devices_summary()),
            "health": lambda: encode(self.health()),
            "eventCounters": lambda: encode(self.counters()),
        }))

    def devices_summary(self) -> list[dict[str, Any]]:
        td_url = self.devices.things.server.td_url
        out = []
        for d in self.devices.running.values():
            state, _ = d.health_state()
            out.append({"id": d.id, "title": d.thing.title, "family": d.family, "td": td_url(d.id),
                        "state": state, "recorded": d.record})
        for r in self.replays.running.values():
            out.append({"id": r.id, "title": r.thing.title, "family": "replay", "td": td_url(r.id),
                        "state": r.state if r.state == "ended" else "ok", "recorded": False})
        return out

    def health(self) -> dict[str, Any]:
        devices = {}
        for d in self.devices.running.values():
            state, reason = d.health_state()
            p = d.pipeline
            devices[d.id] = {"state": state, "reason": reason, "frames": p.frames,
                             "frameErrors": p.frame_errors, "restarts": p.restarts,
                             **d.actions}  # tares, lastTare... (device_actions.py)
        for did, err in self.devices.failed.items():
            devices.setdefault(did, {"state": "failed", "reason": err})
        worst = "ok"
        history = self.history.health()
        if any(v["state"] not in ("ok", "ended") for v in devices.values()) or \
                history.get("state", "ok") != "ok":
            worst = "degraded"
        hub_state = self.hub_state()
        out = {"state": worst if hub_state == "ok" else hub_state,
               "uptimeSeconds": round(time.monotonic() - self.started_at, 3),
               "devices": devices, "history": history}
        registry = loaded_registry()  # never loaded (only add_driver devices): no plugin was needed
        failed_plugins = registry.failed_plugins() if registry is not None else {}
        if failed_plugins:
            out["plugins"] = {"failed": failed_plugins}
        if self.mqtt is not None:  # [mqtt]: the broker link (wott_hub.mqtt.publisher)
            out["mqtt"] = mqtt = self.mqtt.health()
            if mqtt["state"] != "ok" and out["state"] == "ok":
                out["state"] = "degraded"
        if self.foxglove is not None:
            out["foxglove"] = self.foxglove.health()
        return out

    def counters(self) -> dict[str, Any]:
        return {"things": self.plane.counters(), "history": self.history.counters(),
                "overflowDisconnects": self.plane.overflow_disconnects}

    # --- the health watcher -----------------------------------------------------------------

    def start_watching(self) -> None:
        self._task = asyncio.create_task(self._watch())

    def stop_watching(self) -> None:
        if self._task is not None:
            self._task.cancel()

    async def _watch(self, every_s: float = 1.0) -> None:
        """Every ``every_s``: one ``check``; a check that raises is logged and the next one runs."""
        memo: dict[str, Any] = {}
        guard = Guard("health watcher", logger=log)
        while True:
            guard.call("a check", self._check, memo)
            await asyncio.sleep(every_s)

    def _check(self, memo: dict[str, Any]) -> None:
        """Publish ``healthChange`` for each device whose (state, reason) changed since ``memo``, and
        ``health`` when its states changed (the hub's own included; module docstring)."""
        plane = self.plane
        devices: dict[str, tuple[str, str]] = memo.setdefault("devices", {})
        for d in list(self.devices.running.values()):
            now = d.health_state()
            if devices.get(d.id) != now:
                if d.id in devices or now[0] != "ok":
                    plane.publish(HUB_THING_ID, KIND_EVENT, "healthChange", time.time_ns(), encode(
                        {"device": d.id, "state": now[0], "reason": now[1], "timeStamp": time.time_ns()}))
                devices[d.id] = now
        for gone in devices.keys() - self.devices.running.keys():
            del devices[gone]
        health = self.health()
        states = (health["state"], tuple(sorted((k, v.get("state"), v.get("reason"))
                                               for k, v in health["devices"].items())),
                  health["history"].get("state"), (health.get("mqtt") or {}).get("state"))
        if memo.get("states") != states and plane.wants(HUB_THING_ID, KIND_PROPERTY, "health"):
            plane.publish(HUB_THING_ID, KIND_PROPERTY, "health", time.time_ns(), encode(health))
            memo["states"] = states
