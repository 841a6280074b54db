"""The hub: devices in, one servient out, every event recorded.

For each device the hub opens a driver (through the plugin registry), runs a
``FrameProcessor`` on its frames and publishes what they produce on the event
plane: ``skinDeformedDetection`` and ``actionDetection`` events and changes of
the observable ``contactInformation`` property. The plane numbers them, hands
them to the history writer and to subscribers (SSE, WebSocket, wotpy).

Work is done only for someone: a record nobody subscribes to and history does
not keep is not even built (no payload dict, no JSON). The static mesh is
encoded once when the device is exposed and never sent with events.

Lifecycle: ``start`` opens (and migrates) the database, binds the ports,
exposes the hub Thing and the devices, starts the servers; ``stop`` stops the
devices, ends every stream, writes what is queued and closes. ``serve``
(serve.py) wraps both with SIGINT/SIGTERM handling for ``wott-hub run``.

``Hub`` only wires and sequences its parts, each with one job: ``Things``
(serving, things.py), ``HubHistory`` (recording.py), ``Devices`` (devices.py;
pipelines and worker processes in ``wott_hub.runtime``), ``Replays``
(replay.py), ``HubStatus`` (the hub Thing, status.py) and ``HubNetwork``
(``wott_hub.network``, given a ``NetworkPort``).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from wott_hub.config import HubConfig
from wott_hub.config_rules import startup_problems
from wott_hub.errors import ConfigError, InvalidInput, NotFound
from wott_hub.events.plane import EventPlane
from wott_hub.network import HubNetwork
from wott_hub.security import AuditLog, build_policy
from wott_hub.security.tls import server_context
from wott_hub.servient import HUB_THING_ID, HubServer, ServedThing, hub_td

from .device_actions import DeviceActions
from .devices import DeviceRuntime, Devices
from .episodes import Episodes
from .history_api import install as install_history_api
from .identity import hub_identity
from .management import FleetManagement
from .network_port import NetworkPort
from .recording import HubHistory
from .replay import ReplayRuntime, Replays
from .status import HubStatus
from .things import Things
from .usb import UsbAdoption

if TYPE_CHECKING:
    from wott_hub.drivers.base import Driver
    from wott_hub.events.subscriber import Subscriber
    from wott_hub.mqtt.publisher import MqttPublisher
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.robotics.live import FoxgloveLive

__all__ = ["Hub"]


class Hub:
    def __init__(self, config: HubConfig | None = None, *,
                 extra_handlers: Sequence[tuple[Any, ...]] = ()) -> None:
        self.config = cfg = config or HubConfig()
        self._plane = EventPlane(ring_size=cfg.ring_size, max_pending=cfg.max_pending,
                                durability=cfg.history_durability,
                                held_max_bytes=int(cfg.history_queue_mb * 1e6))  # see EventPlane
        # the rules across tables (an open non-loopback hub, [foxglove] off loopback, two endpoints on one
        # port): the same list `wott-hub config check` prints (config_rules.py), refused as one ConfigError
        if problems := startup_problems(cfg):
            raise ConfigError("\n".join(problems))
        self._policy = build_policy(cfg.security, cfg.host)  # who may do what, TLS (wott_hub.security)
        self._audit = AuditLog()
        self._server = HubServer(self._plane, host=cfg.host, http_port=cfg.http_port, ws_port=cfg.ws_port,
                                public_host=cfg.public_host, catalogue_port=cfg.catalogue_port,
                                extra_handlers=extra_handlers, policy=self._policy, audit=self._audit,
                                ssl_context=(server_context(cfg.security.cert, cfg.security.key)
                                             if cfg.security.cert and cfg.security.key else None))
        self._server.ctx.heartbeat_s = cfg.heartbeat_s
        self.state = "stopped"
        self._identity = hub_identity(cfg)  # in every Thing id (identity.py); read or made once, kept
        self._history = HubHistory(cfg, self._plane, self._identity.id)
        self._things = Things(self._plane, self._server, self._history, self._identity)
        self._fleet = Devices(cfg, self._plane, self._things, self._history)
        self._replay = Replays(cfg, self._plane, self._things, self._history)
        self._episodes = Episodes(self._plane, self._things, self._history)  # startEpisode/endEpisode
        # device actions and the hub Thing's addDevice/removeDevice/restartDevice (management.py)
        self._management = FleetManagement(cfg, self._fleet, DeviceActions(self._fleet, self._plane))
        # [usb] adopt: devices opened when plugged in, disconnected when unplugged (usb.py)
        self._usb = UsbAdoption(cfg.usb, self._fleet, self._management) if cfg.usb.enabled else None
        self._status = HubStatus(self._plane, self._fleet, self._replay, self._history, lambda: self.state)
        # TD directory, registrations, mDNS (src/wott_hub/network/)
        self._network = HubNetwork(NetworkPort(cfg, self._server, self._history, self._fleet, self._identity),
                                  cfg.directory, cfg.discovery)
        self._mqtt: MqttPublisher | None = None  # [mqtt]: made when the ports are bound
        self._foxglove: FoxgloveLive | None = None  # [foxglove]: the live endpoint (robotics/live.py)

    @property
    def hub_id(self) -> str:
        return self._identity.id

    # --- lifecycle ------------------------------------------------------------------

    async def start(self) -> None:
        """Serve every TD first (the fleet is visible as soon as possible), then open the
        history database and start the devices' pipelines."""
        self._history.loop = asyncio.get_running_loop()
        self.state = "starting"
        self._status.started_at = time.monotonic()
        self._server.bind()
        if self.config.mqtt.enabled:
            self._start_mqtt()
        if self.config.foxglove.enabled:
            self._start_foxglove()
        td = hub_td(self.config.name, self._server.layout)
        td["id"] = self._identity.hub_thing_id
        self._replay.install(td)  # the replay/stopReplay actions (replay.py)
        install_history_api(td, self._server, self._history)  # historyDevices/Records/Export
        self._episodes.install(td, self._server)
        self._management.install(td)  # fleet actions, and every device's actions (management.py)
        self._status.expose(self._things, td)
        await self._fleet.open_configured()
        await self._server.start(streams_ready=False)
        if self.config.history:
            await asyncio.to_thread(self._history.open)
            self._audit.attach(self._history.engine)  # the audit trail goes into history (audit_log)
        await self._fleet.run_all()
        self._server.ctx.streams_ready.set()
        self._status.start_watching()
        await self._network.start()  # the directory opens on the history database
        self._fleet.live = True
        self._management.start()  # devices that failed to open are retried with backoff
        if self._usb is not None:
            await self._usb.start()
        self.state = "ok"

    async def stop(self) -> None:
        if self.state == "stopped":
            return
        self.state = "stopping"
        self._episodes.end()  # an open episode ends before anything stops recording
        self._fleet.live = False
        if self._mqtt is not None:  # retained state cleared first: a stop cut short leaves none stale
            await self._mqtt.withdraw()
        await self._network.stop()
        self._status.stop_watching()
        self._replay.cancel_all()
        if self._usb is not None:
            await self._usb.stop()
        await self._management.stop()
        await self._fleet.stop()
        if self._mqtt is not None:
            await self._mqtt.stop()
        if self._foxglove is not None:
            self._foxglove.stop()
        await self._server.stop()
        await asyncio.to_thread(self._audit.close)
        await self._history.close()
        self.state = "stopped"

    def hurry(self) -> None:
        """Let the stop under way end without waiting for the database (a second Ctrl-C: ``serve``):
        history spools what it cannot write at once, exports are cancelled; every step of ``stop``
        still runs, in order."""
        self._history.hurry()

    def _start_mqtt(self) -> None:
        """Every TD gets MQTT forms from now on and every served Thing a tap (wott_hub.mqtt)."""
        from dataclasses import replace

        from wott_hub.mqtt.publisher import MqttPublisher
        from wott_hub.td.mqtt import MqttLayout

        m = self.config.mqtt
        host, port = m.host_port(public=True)
        layout = MqttLayout(f"mqtt://{host}:{port}", m.topic_prefix(self.hub_id), m.event_qos)
        self._server.ctx.layout = replace(self._server.layout, mqtt=layout)
        if self._mqtt is None:
            self._mqtt = MqttPublisher(m, layout, self._plane, client_id=f"wott-hub-{self.hub_id}")
            self._server.on_expose.append(self._mqtt.exposed)
            self._server.on_remove.append(self._mqtt.removed)
            self._status.mqtt = self._mqtt
        self._mqtt.layout = layout
        self._mqtt.start()

    def _start_foxglove(self) -> None:
        """The live Foxglove endpoint: every served Thing's channels, fed by taps (wott_hub.robotics)."""
        from wott_hub.robotics.live import FoxgloveLive

        sec = self.config.security
        tls = None
        if sec.cert and sec.key:
            from pathlib import Path

            tls = (Path(sec.cert).read_bytes(), Path(sec.key).read_bytes())
        if self._foxglove is None:
            self._foxglove = FoxgloveLive(self.config.foxglove, self._plane, name=self.config.name, tls=tls)
            self._server.on_expose.append(self._foxglove.exposed)
            self._server.on_remove.append(self._foxglove.removed)
            self._status.foxglove = self._foxglove
        self._foxglove.start()

    async def __aenter__(self) -> Hub:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def add_handlers(self, rules: Sequence[tuple[Any, ...]]) -> None:
        """Mount more routes on the hub's HTTP port (the TD directory, the web twin...)."""
        self._server.add_handlers(rules)

    # --- where things are ---------------------------------------------------------------

    @property
    def http_url(self) -> str:
        return self._server.layout.http_base

    @property
    def ws_url(self) -> str | None:
        return self._server.layout.ws_base

    def td_url(self, thing_id: str) -> str:
        return self._server.td_url(thing_id)

    @property
    def devices(self) -> dict[str, DeviceRuntime]:
        return self._fleet.running

    @property
    def replays(self) -> dict[str, ReplayRuntime]:
        return self._replay.running

    # --- what an embedding program does ------------------------------------------------------

    async def add_device(self, dcfg: DeviceConfig, *, run: bool = True) -> DeviceRuntime:
        """Open a configured device (``wott_hub.plugins.DeviceConfig``) and serve it."""
        return await self._fleet.add_device(dcfg, run=run)

    async def add_driver(self, driver: Driver, *, device_id: str | None = None, family: str | None = None,
                         record: bool = True, run: bool = True) -> DeviceRuntime:
        """Serve an open driver as a device Thing and (``run``) start its pipeline."""
        return await self._fleet.add_driver(driver, device_id=device_id, family=family, record=record,
                                           run=run)

    async def remove_device(self, device_id: str) -> None:
        await self._fleet.remove(device_id)

    async def expose_thing(self, thing_id: str, td: dict[str, Any], *,
                           static_values: dict[str, Any] | None = None,
                           dynamic: dict[str, Callable[[], str]] | None = None, record: bool = False,
                           family: str = "") -> ServedThing:
        """Serve any Thing on the hub (forms and base are rewritten to the hub's layout).

        Its records are published with ``Hub.publish(thing_id, name, value)``;
        ``record`` keeps them in history like a device's.
        """
        return await self._things.expose(thing_id, td, static_values=static_values, dynamic=dynamic,
                                        record=record, family=family)

    async def add_replay(self, device_id: str, *, t_from_ns: int | None = None, t_to_ns: int | None = None,
                         speed: float = 1.0, loop: bool = False, thing_id: str | None = None,
                         names: list[str] | None = None, offset_s: float = 0.0,
                         with_devices: list[str] | None = None) -> ReplayRuntime:
        """Expose a replay Thing re-emitting ``device_id``'s recorded range (``Replays.add``)."""
        return await self._replay.add(device_id, t_from_ns=t_from_ns, t_to_ns=t_to_ns, speed=speed, loop=loop,
                                     thing_id=thing_id, names=names, offset_s=offset_s,
                                     with_devices=with_devices)

    def start_replay(self, rt: ReplayRuntime) -> asyncio.Task[None]:
        return self._replay.start(rt)

    def devices_summary(self) -> list[dict[str, Any]]:
        return self._status.devices_summary()

    def health(self) -> dict[str, Any]:
        return self._status.health()

    def counters(self) -> dict[str, Any]:
        return self._status.counters()

    def publish(self, thing_id: str, name: str, value: Any, *, kind: str = "event") -> int:
        """Publish ``value`` (JSON-able) as an event (or, ``kind="property"``, a property change) of a
        Thing this hub serves: numbered, recorded if the Thing is, and sent to every subscriber on every
        binding. The sequence number it got. The way a Thing of ``expose_thing`` emits."""
        from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, encode

        if kind not in ("event", "property"):
            raise InvalidInput(f"kind must be 'event' or 'property', got {kind!r}")
        if thing_id not in self._plane.streams:
            raise NotFound(f"no Thing {thing_id!r} is served by this hub")
        try:
            data = encode(value)
        except (TypeError, ValueError) as e:
            raise InvalidInput(f"{thing_id} {name}: not a JSON value ({e})") from None
        return self._plane.publish(thing_id, KIND_EVENT if kind == "event" else KIND_PROPERTY, name,
                                   time.time_ns(), data).seq

    def subscribe(self, thing_id: str, name: str | None = None, *, kind: str = "event",
                  after: int | None = None) -> Subscriber:
        """A subscriber to a served Thing's events (``name`` None: all) or property changes: ``async for
        batch in sub.batches()`` gives lists of records (``.seq``, ``.name``, ``.data`` JSON text);
        ``after`` a sequence number to resume after (from history when it is older than the ring);
        ``sub.close()`` ends it."""
        from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY

        if kind not in ("event", "property"):
            raise InvalidInput(f"kind must be 'event' or 'property', got {kind!r}")
        if thing_id not in self._plane.streams:
            raise NotFound(f"no Thing {thing_id!r} is served by this hub")
        return self._plane.subscribe(thing_id, (KIND_EVENT if kind == "event" else KIND_PROPERTY, name),
                                     after=after)

    def flush_history(self, timeout_s: float = 30.0) -> bool:
        """Block until every record published so far is in history (or given up on); False after
        ``timeout_s``, and at once when history is off. For scripts and tests that read it back."""
        writer = self._history.writer
        return writer is not None and writer.flush(timeout_s)

    async def sync_directories(self) -> None:
        """Wait until this hub's directory and those it registers to have every change made so far."""
        await self._network.drain()

    # --- printing -------------------------------------------------------------------

    def describe(self) -> dict[str, Any]:
        """Where everything is: for ``wott-hub run`` to print and scripts to read."""
        return {
            "hub_id": self.hub_id,
            "http": self.http_url,
            "websocket": self.ws_url,
            "catalogue": f"{self.http_url}/wot",
            "hub": self.td_url(HUB_THING_ID),
            "devices": {d.id: self.td_url(d.id) for d in self.devices.values()},
            "replays": {r.id: self.td_url(r.id) for r in self.replays.values()},
            "failed": dict(self._fleet.failed),
            "database": str(self._history.engine.url) if self._history.engine is not None else None,
            "mqtt": self._mqtt.health()["broker"] if self._mqtt is not None else None,
            "foxglove": self._foxglove.url if self._foxglove is not None else None,
            "usb": self._usb.describe() if self._usb is not None else None,
            **self._network.describe(),
        }
