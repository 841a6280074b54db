"""The hub's configuration file (TOML): a ``[hub]`` table and ``[[device]]`` tables.

See docs/hub.md, the commented example docs/hub.example.toml and the generated
reference docs/configuration.md. Every key is declared once below (type with
bounds, default, description) and read by ``wott_hub.configspec`` (msgspec), so
a typo or a value out of bounds is a ``ConfigError`` naming the file, table and
key, not a setting silently ignored or a worker fork bomb. ``[[device]]`` tables
become ``wott_hub.plugins.DeviceConfig`` (``id`` and ``family``; every other key
is a setting of the device's family, checked by its plugin when the device opens).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

from wott_hub.configspec import (
    ConfigError,
    Flag,
    check,
    doc,
    json_schema,
    problems,
    read,
    says,
    suggest,
    table_of,
)
from wott_hub.discovery.usb_config import USB_TABLE, UsbConfig, parse_usb
from wott_hub.mqtt.config import MQTT_TABLE, MqttConfig, parse_mqtt
from wott_hub.network.config import (
    DIRECTORY_TABLE,
    DISCOVERY_TABLE,
    DirectoryConfig,
    DiscoveryConfig,
    parse_directory,
    parse_discovery,
)
from wott_hub.robotics.config import FOXGLOVE_TABLE, FoxgloveConfig, parse_foxglove
from wott_hub.security.config import SECURITY_TABLE, SecurityConfig, parse_security

if TYPE_CHECKING:
    from wott_hub.history.retention import Retention

__all__ = ["DEMO_RETENTION_MB", "HUB_TABLE", "MAX_WORKERS", "ConfigError", "HubConfig", "check_port",
           "config_schema"]

MAX_WORKERS = 64
"""Worker processes at most: beyond a few per core they only add memory and context switches."""

DEMO_RETENTION_MB = 500.0
"""The demo's history bound (``wott-hub run`` without a config): about five hours of the demo fleet."""

Text = Annotated[str, says("a non-empty string", pattern=r"\S")]
Port = Annotated[int, says("a port number (0: any free port)", ge=0, le=65535)]
Days = Annotated[float, says("a positive number", gt=0, le=36_500)]
Megabytes = Annotated[float, says("a positive number", gt=0, le=1e9)]
SpoolMegabytes = Annotated[float, says("a number of MB from 1", ge=1, le=1e6)]
BatchMs = Annotated[float, says("a positive number of milliseconds", gt=0, le=60_000)]
Seconds = Annotated[float, says("a positive number of seconds", gt=0, le=3_600)]
Workers = Annotated[int, says("a whole number of processes (0: none)", ge=0, le=MAX_WORKERS)]
Niceness = Annotated[int, says("a niceness increment (0: the hub's own priority)", ge=0, le=19)]
DeviceIds = Annotated[tuple[Annotated[str, says("a device id")], ...], says("a list of device ids")]
BatchMax = Annotated[int, says("a positive integer", ge=1, le=1_000_000)]
RingSize = Annotated[int, says("a positive integer", ge=1, le=10_000_000)]
MaxPending = Annotated[int, says("a positive integer", ge=1, le=100_000_000)]
HubId = Annotated[str, says("a hub id: lower-case letters, digits and '-', at most 32",
                            pattern=r"^[a-z0-9]([a-z0-9-]{0,30}[a-z0-9])?$")]
Durability = Literal["fast", "committed"]


@dataclass(frozen=True)
class HubConfig:
    name: Text = field(default="wott-hub", metadata=doc("The hub Thing's title."))
    id: HubId | None = field(default=None, metadata=doc(
        "The hub's id, in every Thing id it serves (urn:wott-hub:<id>:device:<device>) and its "
        "mDNS names; default: generated once and kept beside the database (docs/scale-out.md)."))
    host: Text = field(default="127.0.0.1", metadata=doc(
        "Address to listen on (0.0.0.0 for every interface)."))
    public_host: Text | None = field(default=None, metadata=doc(
        "Host name written into TD forms; default: host (127.0.0.1 for 0.0.0.0)."))
    http_port: Port = field(default=8080, metadata=doc(
        "TDs, properties, SSE streams, the Tactile JSON-LD context; 0: any free port."))
    ws_port: Port | None = field(default=8081, metadata=doc(
        "wotpy's WebSocket JSON-RPC binding; false: off."))
    catalogue_port: Port = field(default=0, metadata=doc(
        "wotpy's separate TD catalogue port; 0: off (the catalogue is at /wot)."))
    history: Flag = field(default=True, metadata=doc("Record every event and property change."))
    database: Text = field(default="wott-hub.db", metadata=doc(
        "History database: a SQLite file (relative to the config file) or an SQLAlchemy URL."))
    retention_days: Days | None = field(default=None, metadata=doc(
        "Delete events older than this many days; default: keep them."))
    retention_mb: Megabytes | None = field(default=None, metadata=doc(
        "Keep the history under this many MB (oldest deleted first); default: no limit."))
    history_batch_ms: BatchMs | None = field(default=None, metadata=doc(
        "The history writer commits at most this often (one transaction per batch), ms; default: "
        "100 with history_durability fast, 50 with committed (docs/history.md, \"Commit interval\")."))
    history_batch_max: BatchMax = field(default=20_000, metadata=doc(
        "... or as soon as this many records wait."))
    history_queue_mb: SpoolMegabytes = field(default=256.0, metadata=doc(
        "The records waiting for their batch hold at most this many MB of memory (raw images weigh "
        "~250 kB each); beyond it, while the database lags, new ones are not recorded (and counted)."))
    history_durability: Durability = field(default="fast", metadata=doc(
        "fast: subscribers get a record as soon as it is made, before its batch commits (a crash "
        "can lose what they saw); committed: only once it is in history (docs/reliability.md)."))
    history_process: Flag = field(default=True, metadata=doc(
        "Encode and write the history batches in a process of their own (off the event loop's "
        "GIL; docs/history.md); false: in a thread of the hub's process."))
    history_spool: Text | None = field(default=None, metadata=doc(
        "Folder where records wait while the database cannot take them (store and forward, "
        "docs/reliability.md); default: <database>.spool beside a SQLite file, else "
        "<config file stem>.spool beside the config file, else wott-hub.spool/<hub id> in the working "
        "folder; made only when records must wait."))
    history_spool_mb: SpoolMegabytes = field(default=256.0, metadata=doc(
        "The spool holds at most this many MB; beyond it its oldest records are dropped (and counted)."))
    history_skip: DeviceIds = field(default=(), metadata=doc(
        "Device ids whose events are served live but not recorded."))
    ring_size: RingSize | None = field(default=None, metadata=doc(
        "Records per Thing kept in memory for SSE resume (older ones are read from history); "
        "default: 512 for a recorded Thing, 4096 for one that is not (docs/hub.md, Garbage collection)."))
    max_pending: MaxPending = field(default=100_000, metadata=doc(
        "Records a subscriber may fall behind before it is cut off (it resumes with Last-Event-ID)."))
    heartbeat_s: Seconds = field(default=15.0, metadata=doc(
        "SSE comment on idle streams, s (keeps proxies from closing them)."))
    workers: Workers = field(default=0, metadata=doc(
        f"Processes running the devices' drivers and processing (0: in the hub's process; "
        f"at most {MAX_WORKERS})."))
    worker_nice: Niceness = field(default=10, metadata=doc(
        "How much lower the workers' CPU priority is than the hub's (Unix nice): on a machine "
        "without spare cores, the hub's loop (serving clients) then runs first (docs/hub.md)."))
    devices: tuple[Any, ...] = field(default_factory=tuple)  # wott_hub.plugins.DeviceConfig
    directory: DirectoryConfig = field(default_factory=DirectoryConfig)  # [directory]: on by default
    discovery: DiscoveryConfig = field(default_factory=DiscoveryConfig.off)  # [discovery]: files turn mDNS on
    mqtt: MqttConfig = field(default_factory=MqttConfig)  # [mqtt]: off unless url is set
    security: SecurityConfig = field(default_factory=SecurityConfig)  # [security]: docs/security.md
    foxglove: FoxgloveConfig = field(default_factory=FoxgloveConfig)  # [foxglove]: off unless port is set
    usb: UsbConfig = field(default_factory=UsbConfig)  # [usb]: adopt nothing unless told
    demo: bool = False  # no [[device]] and nothing to adopt: run the demo scene
    source: str = "<defaults>"

    def __post_init__(self) -> None:
        # built in Python or changed by dataclasses.replace (CLI options): the same bounds as a file
        check(self, HUB_TABLE, f"{self.source}: [hub]")

    @classmethod
    def demo_config(cls, **overrides: Any) -> HubConfig:
        """The demo: the demo fleet, announced on its host only, its history kept under
        ``DEMO_RETENTION_MB`` (a demo left running grows its database ~95 MB an hour)."""
        overrides.setdefault("discovery", DiscoveryConfig())
        overrides.setdefault("retention_mb", DEMO_RETENTION_MB)
        return cls(demo=True, source="<demo>", **overrides)

    @classmethod
    def load(cls, path: str | Path) -> HubConfig:
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text())
        except OSError as e:
            raise ConfigError(f"{path}: cannot read: {e.strerror or e}") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise ConfigError(f"{path}: not valid TOML: {e}") from None
        except RecursionError:  # tomllib parses nesting by recursion: a hostile file ends it (issue 48)
            raise ConfigError(f"{path}: not valid TOML: arrays or tables nested too deeply") from None
        cfg = cls.from_dict(data, source=str(path))
        db = cfg.database
        if "://" not in db and not Path(db).is_absolute():  # relative to the config file
            cfg = _replace(cfg, database=str((path.parent / db).resolve()))
        if cfg.history_spool is not None and not Path(cfg.history_spool).is_absolute():
            cfg = _replace(cfg, history_spool=str((path.parent / cfg.history_spool).resolve()))
        return _replace(cfg, security=cfg.security.resolved(path.parent))

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<config>") -> HubConfig:
        """The config of a TOML document; a ``ConfigError`` of one line per problem found in any
        table or device (all of them: ``configspec.problems``), never only the first."""
        errors: list[str] = []
        unknown = sorted(set(data) - set(_TABLES))
        for name in unknown:
            hint = suggest(name, ("device",), "[[{}]]") or suggest(name, _FILE_TABLES, "[{}]") or (
                "; expected [hub], [[device]], [directory], [discovery], [mqtt], [security], [foxglove] "
                "and [usb]")
            errors.append(f"{source}: unknown table [{name}]{hint}")
        hub = data.get("hub", {})
        if isinstance(hub, dict) and hub.get("ws_port") is False:  # documented spelling of "off"
            hub = {**hub, "ws_port": None}
        values: dict[str, Any] = {}
        if found := problems(HUB_TABLE, hub, f"{source}: [hub]"):
            errors += found
        else:
            table = read(HUB_TABLE, hub, f"{source}: [hub]")
            values = {k: getattr(table, k) for k in hub if k in HUB_TABLE.__struct_fields__}
        devices = data.get("device", [])
        parsed = _devices(devices, source, errors)
        ids = {d.id for d in parsed}
        skip = set(values.get("history_skip", ()))
        if skip - ids and isinstance(devices, list) and len(parsed) == len(devices):  # else: said already
            errors.append(f"{source}: [hub].history_skip names unknown device(s) {sorted(skip - ids)}")
        tables: dict[str, Any] = {}
        for key, (model, parse) in _TABLES.items():
            if model is None:
                continue
            given = data.get(key, {})
            if found := problems(model, given, f"{source}: [{key}]"):
                errors += found
                continue
            try:
                tables[key] = parse(given, source)  # rules across keys (cert and key go together...)
            except ConfigError as e:
                errors.append(str(e))
        if errors:
            raise ConfigError("\n".join(errors))
        adopting = "usb" in tables and tables["usb"].enabled
        return cls(devices=tuple(parsed), demo=not parsed and not adopting, source=source, **tables, **values)

    @property
    def commit_interval_s(self) -> float:
        """Seconds between history commits: ``history_batch_ms``, else by durability. Each commit
        writes every index page its batch touched, ~110 at 32 devices whatever the batch's size:
        fewer commits cost the history process less CPU but arrive as longer bursts, which delay
        the subscribers' clients on a busy machine (docs/history.md, "Commit interval"); where a
        subscriber waits for the commit (committed), the shorter wait is worth more."""
        if self.history_batch_ms is not None:
            return self.history_batch_ms / 1000
        return 0.05 if self.history_durability == "committed" else 0.1

    @property
    def retention(self) -> Retention:
        from wott_hub.history.retention import Retention

        return Retention(days=self.retention_days, max_mb=self.retention_mb)


HUB_TABLE = table_of(HubConfig, "hub", exclude=("devices", "directory", "discovery", "mqtt", "security",
                                                "foxglove", "usb", "demo", "source"))
"""The ``[hub]`` table as it is written in a file (JSON Schema: ``config_schema``)."""

_FILE_TABLES = ("hub", "directory", "discovery", "mqtt", "security", "foxglove", "usb")
_TABLES: dict[str, tuple[Any, Any]] = {  # a file's tables: their declared model and their parser
    "hub": (None, None), "device": (None, None),
    "directory": (DIRECTORY_TABLE, parse_directory), "discovery": (DISCOVERY_TABLE, parse_discovery),
    "mqtt": (MQTT_TABLE, parse_mqtt), "security": (SECURITY_TABLE, parse_security),
    "foxglove": (FOXGLOVE_TABLE, parse_foxglove), "usb": (USB_TABLE, parse_usb),
}


def _devices(tables: Any, source: str, errors: list[str]) -> list[Any]:
    """The ``[[device]]`` tables as ``DeviceConfig``s; each problem (every one) appended to ``errors``.
    The family's settings are not checked here (that needs the plugins: ``wott-hub config check``)."""
    if not isinstance(tables, list):
        errors.append(f"{source}: 'device' must be an array of tables ([[device]])")
        return []
    from wott_hub.plugins import DeviceConfig
    from wott_hub.plugins.model import DeviceTable

    parsed = []
    ids: dict[str, str] = {}  # casefold -> the first id written so
    for i, dev in enumerate(tables):
        where = f"{source}: device[{i}]"
        if found := problems(DeviceTable, dev, where):
            errors += found
            continue
        cfg = DeviceConfig.from_table(dev, where=where)
        key = cfg.id.casefold()  # ids are one regardless of case: URLs, addDevice, WebSocket names
        if key in ids:
            same = "" if ids[key] == cfg.id else f" ({ids[key]!r}: ids are compared regardless of case)"
            errors.append(f"{where}.id: {cfg.id!r} is used by another device{same}")
        elif key == "hub":
            errors.append(f"{where}.id: 'hub' is the hub's own Thing; choose another id")
        ids.setdefault(key, cfg.id)
        parsed.append(cfg)
    return parsed


def _replace(cfg: HubConfig, **changes: Any) -> HubConfig:
    from dataclasses import replace

    return replace(cfg, **changes)


def check_port(value: int | None, option: str = "--port") -> int | None:
    """A port given on the command line, checked as ``[hub]`` ports are: ``--port 70000`` is a
    ConfigError naming the option (the socket would otherwise wrap it to 4464)."""
    if value is not None and (isinstance(value, bool) or not 0 <= value <= 65535):
        raise ConfigError(f"{option}: a port number (0: any free port), got {value!r}; "
                          "must be from 0 to 65535")
    return value


def config_schema() -> dict[str, Any]:
    """The JSON Schema of a whole hub config file: ``[hub]``, ``[directory]``, ``[discovery]``,
    ``[mqtt]``, ``[security]``, ``[foxglove]``, ``[usb]`` and ``[[device]]`` (whose other keys are the
    family's settings: ``wott-hub plugins families``)."""
    from wott_hub.plugins.model import DeviceTable

    defs: dict[str, Any] = {}
    props: dict[str, Any] = {}
    for key, model in (("hub", HUB_TABLE), ("directory", DIRECTORY_TABLE), ("discovery", DISCOVERY_TABLE),
                       ("mqtt", MQTT_TABLE), ("security", SECURITY_TABLE), ("foxglove", FOXGLOVE_TABLE),
                       ("usb", USB_TABLE)):
        schema = json_schema(model)
        defs.update(schema.get("$defs", {}))
        props[key] = {"$ref": schema["$ref"]} if "$ref" in schema else schema
    device = json_schema(DeviceTable)
    defs.update(device.get("$defs", {}))
    props["device"] = {"type": "array", "items": {"$ref": device["$ref"]}}
    defs["hub"]["properties"]["ws_port"]["anyOf"].append({"const": False})  # the file's spelling of "off"
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "wott-hub configuration",
            "type": "object", "properties": props, "additionalProperties": False, "$defs": defs}
