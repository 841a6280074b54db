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
from wott_hub.events.plane import EventPlane
from wott_hub.network import HubNetwork
from wott_hub.security import AuditLog, build_policy
from wott_hub.security.tls import server_context
from wott_hub.servient import HUB_THING_ID, HubServer, ServedThing, hub_td

from .device_actions import DeviceActions
from .devices import DeviceRuntime, Devices
from .history_api import install as install_history_api
from .identity import hub_identity
from .management import FleetManagement
from .network_port import NetworkPort
from .recording import HubHistory
from .replay import ReplayRuntime, Replays
from .status import HubStatus
from .things import Things

if TYPE_CHECKING:
    from sqlalchemy import Engine

    from wott_hub.drivers.base import Driver
    from wott_hub.history import HistoryReader, HistoryWriter
    from wott_hub.mqtt.publisher import MqttPublisher
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.runtime.pool import WorkerPool

__all__ = ["Hub"]


class Hub:
    def __init__(self, config: HubConfig | None = None, *,
                 extra_handlers: Sequence[tuple[Any, ...]] = ()) -> None:
        self.config = cfg = config or HubConfig()
        self.plane = EventPlane(ring_size=cfg.ring_size, max_pending=cfg.max_pending,
                                durability=cfg.history_durability)
        # who may do what, TLS (wott_hub.security): a ConfigError here refuses an open non-loopback hub
        self.policy = build_policy(cfg.security, cfg.host)
        self.audit = AuditLog()
        self.server = HubServer(self.plane, host=cfg.host, http_port=cfg.http_port, ws_port=cfg.ws_port,
                                public_host=cfg.public_host, catalogue_port=cfg.catalogue_port,
                                extra_handlers=extra_handlers, policy=self.policy, audit=self.audit,
                                ssl_context=(server_context(cfg.security.cert, cfg.security.key)
                                             if cfg.security.cert and cfg.security.key else None))
        self.server.ctx.heartbeat_s = cfg.heartbeat_s
        self.state = "stopped"
        self.identity = hub_identity(cfg)  # in every Thing id (identity.py); read or made once, kept
        self.history = HubHistory(cfg, self.plane, self.identity.id)
        self.things = Things(self.plane, self.server, self.history, self.identity)
        self.fleet = Devices(cfg, self.plane, self.things, self.history)
        self.replay = Replays(cfg, self.plane, self.things, self.history)
        # device actions and the hub Thing's addDevice/removeDevice/restartDevice (management.py)
        self.management = FleetManagement(cfg, self.fleet, DeviceActions(self.fleet, self.plane))
        self.status = HubStatus(self.plane, self.fleet, self.replay, self.history, lambda: self.state)
        # TD directory, registrations, mDNS (src/wott_hub/network/)
        self.network = HubNetwork(NetworkPort(cfg, self.server, self.history, self.fleet, self.identity),
                                  cfg.directory, cfg.discovery)
        self.mqtt: MqttPublisher | None = None  # [mqtt]: made when the ports are bound

    @property
    def hub_id(self) -> str:
        return self.identity.id

    # --- lifecycle ------------------------------------------------------------------

    async def start(self) -> None:
        """Serve every TD first (the fleet is visible as soon as possible), then open the
        history database and start the devices' pipelines."""
        self.history.loop = asyncio.get_running_loop()
        self.state = "starting"
        self.status.started_at = time.monotonic()
        self.server.bind()
        if self.config.mqtt.enabled:
            self._start_mqtt()
        td = hub_td(self.config.name, self.server.layout)
        td["id"] = self.identity.hub_thing_id
        self.replay.install(td)  # the replay/stopReplay actions (replay.py)
        install_history_api(td, self.server, self.history)  # historyDevices/Records/Export
        self.management.install(td)  # fleet actions, and every device's actions (management.py)
        self.status.expose(self.things, td)
        await self.fleet.open_configured()
        await self.server.start(streams_ready=False)
        if self.config.history:
            await asyncio.to_thread(self.history.open)
            self.audit.attach(self.history.engine)  # the audit trail goes into history (audit_log)
        await self.fleet.run_all()
        self.server.ctx.streams_ready.set()
        self.status.start_watching()
        await self.network.start()  # the directory opens on the history database
        self.fleet.live = True
        self.management.start()  # devices that failed to open are retried with backoff
        self.state = "ok"

    async def stop(self) -> None:
        if self.state == "stopped":
            return
        self.state = "stopping"
        self.fleet.live = False
        await self.network.stop()
        self.status.stop_watching()
        self.replay.cancel_all()
        await self.management.stop()
        await self.fleet.stop()
        if self.mqtt is not None:
            await self.mqtt.stop()
        await self.server.stop()
        await asyncio.to_thread(self.audit.close)
        await self.history.close()
        self.state = "stopped"

    def _start_mqtt(self) -> None:
        """Every TD gets MQTT forms from now on and every served Thing a tap (wott_hub.mqtt)."""
        from dataclasses import replace

        from wott_hub.mqtt.publisher import MqttPublisher
        from wott_hub.td.mqtt import MqttLayout

        m = self.config.mqtt
        host, port = m.host_port(public=True)
        layout = MqttLayout(f"mqtt://{host}:{port}", m.topic_prefix(self.hub_id), m.event_qos)
        self.server.ctx.layout = replace(self.server.layout, mqtt=layout)
        if self.mqtt is None:
            self.mqtt = MqttPublisher(m, layout, self.plane, client_id=f"wott-hub-{self.hub_id}")
            self.server.on_expose.append(self.mqtt.exposed)
            self.server.on_remove.append(self.mqtt.removed)
            self.status.mqtt = self.mqtt
        self.mqtt.layout = layout
        self.mqtt.start()

    async def __aenter__(self) -> Hub:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def add_handlers(self, rules: Sequence[tuple[Any, ...]]) -> None:
        """Mount more routes on the hub's HTTP port (the TD directory, the web twin...)."""
        self.server.add_handlers(rules)

    # --- where things are ---------------------------------------------------------------

    @property
    def http_url(self) -> str:
        return self.server.layout.http_base

    @property
    def ws_url(self) -> str | None:
        return self.server.layout.ws_base

    def td_url(self, thing_id: str) -> str:
        return self.server.td_url(thing_id)

    @property
    def devices(self) -> dict[str, DeviceRuntime]:
        return self.fleet.running

    @property
    def replays(self) -> dict[str, ReplayRuntime]:
        return self.replay.running

    @property
    def pool(self) -> WorkerPool | None:
        """The worker processes (``[hub] workers`` > 0)."""
        return self.fleet.pool

    @property
    def engine(self) -> Engine | None:
        return self.history.engine

    @property
    def writer(self) -> HistoryWriter | None:
        return self.history.writer

    @property
    def reader(self) -> HistoryReader | None:
        return self.history.reader

    # --- what an embedding program does ------------------------------------------------------

    async def add_device(self, dcfg: DeviceConfig, *, run: bool = True) -> DeviceRuntime:
        """Open a configured device (``wott_hub.plugins.DeviceConfig``) and serve it."""
        return await self.fleet.add_device(dcfg, run=run)

    async def add_driver(self, driver: Driver, *, device_id: str | None = None, family: str | None = None,
                         record: bool = True, run: bool = True) -> DeviceRuntime:
        """Serve an open driver as a device Thing and (``run``) start its pipeline."""
        return await self.fleet.add_driver(driver, device_id=device_id, family=family, record=record,
                                           run=run)

    async def remove_device(self, device_id: str) -> None:
        await self.fleet.remove(device_id)

    async def expose_thing(self, thing_id: str, td: dict[str, Any], *,
                           static_values: dict[str, Any] | None = None,
                           dynamic: dict[str, Callable[[], str]] | None = None, record: bool = False,
                           family: str = "") -> ServedThing:
        """Serve any Thing on the hub (forms and base are rewritten to the hub's layout).

        Its records are published with ``hub.plane.publish(thing_id, ...)``;
        ``record`` keeps them in history like a device's.
        """
        return await self.things.expose(thing_id, td, static_values=static_values, dynamic=dynamic,
                                        record=record, family=family)

    async def add_replay(self, device_id: str, *, t_from_ns: int | None = None, t_to_ns: int | None = None,
                         speed: float = 1.0, loop: bool = False, thing_id: str | None = None,
                         names: list[str] | None = None, offset_s: float = 0.0,
                         with_devices: list[str] | None = None) -> ReplayRuntime:
        """Expose a replay Thing re-emitting ``device_id``'s recorded range (``Replays.add``)."""
        return await self.replay.add(device_id, t_from_ns=t_from_ns, t_to_ns=t_to_ns, speed=speed, loop=loop,
                                     thing_id=thing_id, names=names, offset_s=offset_s,
                                     with_devices=with_devices)

    def start_replay(self, rt: ReplayRuntime) -> asyncio.Task[None]:
        return self.replay.start(rt)

    def devices_summary(self) -> list[dict[str, Any]]:
        return self.status.devices_summary()

    def health(self) -> dict[str, Any]:
        return self.status.health()

    def counters(self) -> dict[str, Any]:
        return self.status.counters()

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
            "failed": dict(self.fleet.failed),
            "database": str(self.engine.url) if self.engine is not None else None,
            "mqtt": self.mqtt.health()["broker"] if self.mqtt is not None else None,
            **self.network.describe(),
        }
