"""The ``[foxglove]`` table of the hub config: the live Foxglove WebSocket endpoint.

Declared like the other tables (``wott_hub.configspec``); nothing here imports foxglove: a
config without ``[foxglove]`` never loads it. ``check_bind`` holds the trust rule (docs/robotics.md):
the endpoint is on loopback unless told otherwise, and a non-loopback address is refused unless
``insecure`` is set (here or ``wott-hub run --insecure``), because the protocol's connection carries
no hub token the server could check: foxglove-sdk's server has no authentication hook (TLS yes:
it serves wss with the hub's ``[security]`` certificate).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any

from wott_hub.configspec import ConfigError, Flag, check, doc, read, says, table_of
from wott_hub.security import is_loopback

__all__ = ["FOXGLOVE_TABLE", "FoxgloveConfig", "check_bind", "parse_foxglove"]

Port = Annotated[int, says("a port number (0: any free port)", ge=0, le=65535)]
Host = Annotated[str, says("a non-empty host or address", pattern=r"\S")]
Hz = Annotated[float, says("a rate in Hz from 1 to 120", ge=1, le=120)]
Backlog = Annotated[int, says("a number of messages from 64 to 1,000,000", ge=64, le=1_000_000)]
Millimetres = Annotated[float, says("a positive number of mm", gt=0, le=1000)]


@dataclass(frozen=True)
class FoxgloveConfig:
    port: Port | None = field(default=None, metadata=doc(
        "Serve the Foxglove WebSocket protocol on this port (0: any free port); unset: off. "
        "wott-hub run --foxglove-port N does the same."))
    host: Host = field(default="127.0.0.1", metadata=doc(
        "Address of the Foxglove endpoint; another than loopback needs insecure (the protocol carries "
        "no token)."))
    scene_hz: Hz = field(default=30.0, metadata=doc(
        "Scenes (deformation, contacts) drawn at most this often per device; the latest state is "
        "always drawn."))
    color_max_mm: Millimetres = field(default=2.0, metadata=doc(
        "Intensity drawn full red in the deformation scene, mm."))
    backlog: Backlog = field(default=8192, metadata=doc(
        "Messages kept per client that reads slowly; beyond, its oldest are dropped (never the hub's "
        "other clients)."))
    insecure: Flag = field(default=False, metadata=doc(
        "Serve the Foxglove endpoint on a non-loopback host to anyone who can reach it."))

    def __post_init__(self) -> None:
        check(self, FOXGLOVE_TABLE, "[foxglove]")

    @property
    def enabled(self) -> bool:
        return self.port is not None


FOXGLOVE_TABLE = table_of(FoxgloveConfig, "foxglove")
"""The ``[foxglove]`` table as it is written in a file."""


def parse_foxglove(table: Any, source: str) -> FoxgloveConfig:
    where = f"{source}: [foxglove]"
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: must be a table")
    t = read(FOXGLOVE_TABLE, table, where)
    cfg = FoxgloveConfig(**{k: getattr(t, k) for k in FOXGLOVE_TABLE.__struct_fields__})
    if table and cfg.port is None:
        raise ConfigError(f"{where}.port: missing; the port to serve Foxglove on (0: any free port)")
    return cfg


def check_bind(cfg: FoxgloveConfig, insecure: bool) -> None:
    """``ConfigError`` (one line) for a non-loopback endpoint nobody said may be open."""
    if cfg.enabled and not is_loopback(cfg.host) and not (cfg.insecure or insecure):
        raise ConfigError(
            f"refusing to serve Foxglove on {cfg.host}: the Foxglove WebSocket protocol carries no token the "
            "hub could check, so anyone who reaches the port reads every device; keep [foxglove] host on "
            "127.0.0.1 (an SSH tunnel: ssh -L 8765:127.0.0.1:8765 hub), or set [foxglove] insecure = true "
            "(or run with --insecure)")
