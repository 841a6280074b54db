"""The hub's identity: one short id, generated once and kept, in every Thing id it serves.

Two hubs registering into one directory must never serve the same Thing id, and a
hub restarted must serve the same ids as before (clients, the directory and history
key on them). So every id carries the hub's id::

    urn:wott-hub:<hub-id>:hub               the hub Thing
    urn:wott-hub:<hub-id>:device:<device>   a device ([[device]] id)
    urn:wott-hub:<hub-id>:replay:<device>   a replay of a recorded device

URL paths (``/wot/<device>``), history (keyed by the device id) and MQTT topics
(``wott/<hub-id>/<device>/...``) keep the short names.

Where the hub id comes from, first found wins:

1. ``[hub] id`` in the config (e.g. ``"cell-3"``): an operator's name, stable by definition;
2. a state file, read if it exists, else written once with a new random id
   (``h`` + 11 hex digits of a UUID4): ``<database>.hub-id`` beside a SQLite
   history database, else ``<config file stem>.hub-id`` beside the config file
   (a hub on PostgreSQL: the database is shared by hubs, a file is not);
3. nothing to keep it in (no SQLite file, no config file): a random id for this run
   only, logged, so that ids stay unique even when they cannot stay stable.

A hub id is a DNS label (lower-case letters, digits, '-', at most 32 characters): it
goes into URNs, MQTT topics and mDNS host names unchanged.
"""

from __future__ import annotations

import logging
import os
import re
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from wott_hub.errors import ConfigError

if TYPE_CHECKING:
    from wott_hub.config import HubConfig

__all__ = ["HUB_ID_PATTERN", "HubIdentity", "hub_identity", "new_hub_id"]

log = logging.getLogger("wott_hub.hub")

HUB_ID_PATTERN = r"^[a-z0-9]([a-z0-9-]{0,30}[a-z0-9])?$"
_HUB_ID = re.compile(HUB_ID_PATTERN)


def new_hub_id() -> str:
    return "h" + uuid.uuid4().hex[:11]


@dataclass(frozen=True)
class HubIdentity:
    id: str
    source: str  # "config", the state file's path, or "this run only"

    @property
    def urn(self) -> str:
        return f"urn:wott-hub:{self.id}"

    @property
    def prefix(self) -> str:
        """What every Thing id of this hub starts with."""
        return f"{self.urn}:"

    @property
    def hub_thing_id(self) -> str:
        return f"{self.urn}:hub"

    def device_id(self, device: str) -> str:
        return f"{self.urn}:device:{device}"

    def replay_id(self, device: str) -> str:
        return f"{self.urn}:replay:{device}"


def _check(value: str, where: str) -> str:
    if not _HUB_ID.match(value):
        raise ConfigError(f"{where}: hub id {value!r} must be lower-case letters, digits and '-' "
                          "(at most 32, not starting or ending with '-')")
    return value


def _state_file(cfg: HubConfig) -> Path | None:
    db = cfg.database
    if cfg.history and "://" not in db and db != ":memory:":
        path = Path(db)
        return path.with_name(path.name + ".hub-id")
    if cfg.source and not cfg.source.startswith("<"):
        conf = Path(cfg.source)
        return conf.with_name(conf.stem + ".hub-id")
    return None


def _read_small(path: Path) -> str:
    """The state file's text: a regular file of a few bytes. A FIFO there never blocks the start
    (opened non-blocking) and a link to a device is never read (issue 48: whatever the hub reads
    beside its database is a regular file, read in bounded size)."""
    import stat

    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ConfigError(f"{path}: the hub id file is not a regular file; remove it (a new id is made)")
        data = os.read(fd, 256)
    finally:
        os.close(fd)
    return data.decode("utf-8", "replace")


def hub_identity(cfg: HubConfig) -> HubIdentity:
    """The hub's identity for this config (reads or writes the state file: call it once)."""
    configured = getattr(cfg, "id", None)
    if configured:
        return HubIdentity(_check(configured, f"{cfg.source}: [hub].id"), "config")
    path = _state_file(cfg)
    if path is None:
        hub_id = new_hub_id()
        log.info("hub id %s for this run only (no SQLite database or config file to keep it in)", hub_id)
        return HubIdentity(hub_id, "this run only")
    try:
        return HubIdentity(_check(_read_small(path).strip(), str(path)), str(path))
    except FileNotFoundError:
        pass
    except OSError as e:
        raise ConfigError(f"{path}: cannot read the hub id: {e.strerror or e}") from None
    hub_id = new_hub_id()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(hub_id + "\n")
        tmp.replace(path)  # atomic: a crash never leaves half an id
    except OSError as e:
        raise ConfigError(f"{path}: cannot store the new hub id: {e.strerror or e}") from None
    log.info("new hub id %s, kept in %s", hub_id, path)
    return HubIdentity(hub_id, str(path))
