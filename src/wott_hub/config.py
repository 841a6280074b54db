"""The hub's configuration file (TOML): a ``[hub]`` table and ``[[device]]`` tables.

See docs/hub.md and the commented example docs/hub.example.toml. Every key is
checked here, so a typo is an error naming the file, table and key, not a
setting silently ignored. ``[[device]]`` tables become
``wott_hub.plugins.DeviceConfig`` (``id`` and ``family``; every other key is a
setting of the device's family, checked by its plugin when the device opens).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from wott_hub.network.config import DirectoryConfig, DiscoveryConfig, parse_directory, parse_discovery

__all__ = ["ConfigError", "HubConfig"]


class ConfigError(ValueError):
    """A config file that cannot be used, with the file, table and key at fault."""


@dataclass(frozen=True)
class HubConfig:
    name: str = "wott-hub"
    host: str = "127.0.0.1"
    public_host: str | None = None  # host name written into TD forms; default: host
    http_port: int = 8080
    ws_port: int | None = 8081  # wotpy's WebSocket JSON-RPC binding; None: off
    catalogue_port: int = 0  # wotpy's separate TD catalogue port; 0: off (the catalogue is at /wot)
    history: bool = True
    database: str = "wott-hub.db"  # a file path (SQLite) or an SQLAlchemy URL
    retention_days: float | None = None
    retention_mb: float | None = None
    history_batch_ms: float = 50.0
    history_batch_max: int = 20_000
    history_skip: tuple[str, ...] = ()  # device ids whose events are not recorded
    ring_size: int = 4096  # records per Thing kept in memory for SSE resume
    max_pending: int = 100_000  # records a subscriber may fall behind before it is cut off
    heartbeat_s: float = 15.0
    workers: int = 0  # processes running the devices' drivers and processing; 0: in the hub's process
    devices: tuple[Any, ...] = field(default_factory=tuple)  # wott_hub.plugins.DeviceConfig
    directory: DirectoryConfig = field(default_factory=DirectoryConfig)  # [directory]: on by default
    discovery: DiscoveryConfig = field(default_factory=DiscoveryConfig.off)  # [discovery]: files turn mDNS on
    demo: bool = False  # no [[device]]: run the demo scene
    source: str = "<defaults>"

    @classmethod
    def demo_config(cls, **overrides: Any) -> HubConfig:
        overrides.setdefault("discovery", DiscoveryConfig())  # the demo announces (on its host only)
        return cls(demo=True, source="<demo>", **overrides)

    @classmethod
    def load(cls, path: str | Path) -> HubConfig:
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text())
        except OSError as e:
            raise ConfigError(f"{path}: cannot read: {e.strerror or e}") from None
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"{path}: not valid TOML: {e}") from None
        cfg = cls.from_dict(data, source=str(path))
        db = cfg.database
        if "://" not in db and not Path(db).is_absolute():  # relative to the config file
            cfg = _replace(cfg, database=str((path.parent / db).resolve()))
        return cfg

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<config>") -> HubConfig:
        unknown = set(data) - {"hub", "device", "directory", "discovery"}
        if unknown:
            raise ConfigError(f"{source}: unknown table(s) {sorted(unknown)}; expected [hub], [[device]], "
                              "[directory] and [discovery]")
        hub = data.get("hub", {})
        if not isinstance(hub, dict):
            raise ConfigError(f"{source}: [hub] must be a table")
        known = {f.name for f in fields(cls)} - {"devices", "demo", "source", "directory", "discovery"}
        values: dict[str, Any] = {}
        for key, value in hub.items():
            if key not in known:
                raise ConfigError(f"{source}: [hub].{key}: unknown key (known: {', '.join(sorted(known))})")
            values[key] = _check(key, value, f"{source}: [hub].{key}")
        devices = data.get("device", [])
        if not isinstance(devices, list):
            raise ConfigError(f"{source}: 'device' must be an array of tables ([[device]])")
        from wott_hub.drivers.base import DriverError
        from wott_hub.plugins import DeviceConfig

        parsed = []
        ids: set[str] = set()
        for i, table in enumerate(devices):
            where = f"{source}: device[{i}]"
            try:
                cfg = DeviceConfig.from_table(table, where=where)
            except DriverError as e:
                raise ConfigError(str(e)) from None
            if cfg.id in ids:
                raise ConfigError(f"{where}.id: {cfg.id!r} is used by another device")
            if cfg.id == "hub":
                raise ConfigError(f"{where}.id: 'hub' is the hub's own Thing; choose another id")
            ids.add(cfg.id)
            parsed.append(cfg)
        skip = set(values.get("history_skip", ()))
        if skip - ids:
            raise ConfigError(f"{source}: [hub].history_skip names unknown device(s) {sorted(skip - ids)}")
        return cls(devices=tuple(parsed), demo=not parsed, source=source,
                   directory=parse_directory(data.get("directory", {}), source),
                   discovery=parse_discovery(data.get("discovery", {}), source), **values)

    @property
    def retention(self):
        from wott_hub.history.retention import Retention

        return Retention(days=self.retention_days, max_mb=self.retention_mb)


def _replace(cfg: HubConfig, **changes: Any) -> HubConfig:
    from dataclasses import replace

    return replace(cfg, **changes)


_PORTS = ("http_port", "ws_port", "catalogue_port")
_POSITIVE = ("retention_days", "retention_mb", "history_batch_ms", "heartbeat_s")
_COUNTS = ("history_batch_max", "ring_size", "max_pending")
_NATURALS = ("workers",)
_STRINGS = ("name", "host", "public_host", "database")


def _check(key: str, value: Any, where: str) -> Any:
    if key in _PORTS:
        if key == "ws_port" and value is False:
            return None
        if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 65535:
            raise ConfigError(f"{where}: a port number 0-65535 (0: any free port), got {value!r}")
        return value
    if key in _POSITIVE:
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            raise ConfigError(f"{where}: a positive number, got {value!r}")
        return float(value)
    if key in _COUNTS:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f"{where}: a positive integer, got {value!r}")
        return value
    if key in _NATURALS:
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise ConfigError(f"{where}: a whole number >= 0, got {value!r}")
        return value
    if key in _STRINGS:
        if not isinstance(value, str) or not value.strip():
            raise ConfigError(f"{where}: a non-empty string, got {value!r}")
        return value
    if key == "history":
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: true or false, got {value!r}")
        return value
    if key == "history_skip":
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{where}: a list of device ids, got {value!r}")
        return tuple(value)
    raise ConfigError(f"{where}: unknown key")
