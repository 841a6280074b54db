"""``wott-hub run``: the hub. No config: the demo scene on 127.0.0.1.

A config is checked as ``wott-hub config check`` checks it before anything starts: every
problem (tables, keys, each device's settings, the ``[security]`` files) is one ``error:``
line and the hub does not start (exit 2). A device whose settings are right but which does
not open (a serial port unplugged) does not stop the hub: it is listed FAILED in the banner
and retried (docs/devices.md).

The banner says where everything is, counts what it lists, and gives the two URLs a new
user tries first: the twin in a browser and a ``curl`` line that streams a device's events
(SSE needs ``Accept: text/event-stream``; without it the URL answers one JSON value).
"""

from __future__ import annotations

import time
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.hub import Hub

__all__ = ["LogLevel", "app", "banner", "run"]

_T0 = time.monotonic()

app = typer.Typer(rich_markup_mode=None)


class LogLevel(StrEnum):
    debug = "debug"
    info = "info"
    warning = "warning"
    error = "error"
    critical = "critical"


@app.command(short_help="Run the hub (no config: the demo fleet).")
def run(
    config: Path = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                                help="Hub config (TOML, see docs/hub.md). Without it: the demo scene."),
    host: str = typer.Option(None, help="Address to listen on (default: config, else 127.0.0.1)."),
    port: int = typer.Option(None, "--port", help="HTTP port (TDs, properties, SSE); 0 = any free port."),
    ws_port: int = typer.Option(None, "--ws-port", help="WebSocket port (wotpy JSON-RPC); 0 = any free."),
    database: str = typer.Option(None, help="History database: a file (SQLite) or an SQLAlchemy URL."),
    no_history: bool = typer.Option(False, "--no-history", help="Do not record events."),
    as_json: bool = typer.Option(False, "--json", help="Print where everything is as one JSON line."),
    log_level: LogLevel = typer.Option(LogLevel.warning, case_sensitive=False, help="Logging level."),
    tokens: Path = typer.Option(None, "--tokens", dir_okay=False,
                                help="File of hashed tokens (wott-hub tokens create --file); default: "
                                     "the tokens_file of the config's [security] table."),
    cert: Path = typer.Option(None, "--cert", exists=True, dir_okay=False,
                              help="PEM certificate: serve https and wss."),
    key: Path = typer.Option(None, "--key", exists=True, dir_okay=False, help="PEM private key of --cert."),
    insecure: bool = typer.Option(False, "--insecure",
                                  help="Serve everyone without credentials on a non-loopback address."),
    foxglove_port: int = typer.Option(None, "--foxglove-port",
                                      help="Serve Foxglove's WebSocket protocol on this port (0: any free; "
                                           "[foxglove] port; docs/robotics.md)."),
) -> None:
    """Run the hub: one WoT servient for every device, SSE and WebSocket events, history.

    A config with mistakes is refused before anything starts (one line per mistake; see
    'wott-hub config check'). Ctrl-C or SIGTERM stops the hub cleanly: devices stop,
    streams end, queued events are written.
    """
    import asyncio
    import dataclasses
    import json
    import logging

    from wott_hub.config import ConfigError, HubConfig, check_port
    from wott_hub.config_rules import startup_problems

    from ._check import check_files
    from .config import load_checked

    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # a ConfigError (or a HistoryError when the hub starts) is reported by ``cli``: one line each
    check_port(port, "--port"), check_port(ws_port, "--ws-port")  # 70000 would wrap to 4464
    check_port(foxglove_port, "--foxglove-port")
    if config is not None:
        cfg, _, problems = load_checked(config)
        if cfg.demo:  # no [[device]]: the plugins' demo devices, whose mistakes mark them, not the hub
            problems = check_files(cfg)
        if problems:
            raise ConfigError("\n".join(problems))
    else:
        cfg = HubConfig.demo_config()
    changes: dict[str, Any] = {k: v for k, v in {"host": host, "http_port": port, "ws_port": ws_port,
                                 "database": database}.items() if v is not None}
    if no_history:
        changes["history"] = False
    paths = {"tokens_file": tokens, "cert": cert, "key": key}
    sec: dict[str, Any] = {k: str(v.resolve()) for k, v in paths.items() if v is not None}
    if insecure:
        sec["insecure"] = True
    if sec:  # docs/security.md
        changes["security"] = dataclasses.replace(cfg.security, **sec)
    if foxglove_port is not None:
        changes["foxglove"] = dataclasses.replace(cfg.foxglove, port=foxglove_port)
    cfg = dataclasses.replace(cfg, **changes)  # checked again, as a file's values are
    if problems := check_files(cfg) if sec else startup_problems(cfg):  # with the command line's values
        raise ConfigError("\n".join(problems))

    from wott_hub.hub import serve

    _warn_failed_plugins()

    def ready(hub: Hub) -> None:
        info = hub.describe()
        info["ready_s"] = round(time.monotonic() - _T0, 3)
        if as_json:
            typer.echo(json.dumps(info), nl=True)
        else:
            typer.echo("\n".join(banner(hub, info, cfg)))

    try:
        asyncio.run(serve(cfg, ready=ready))
    except OSError as e:  # typically a port in use
        hint = "" if "(choose" in str(e) else " (choose other ports with --port/--ws-port or in [hub])"
        typer.echo(f"error: {e}{hint}", err=True)
        raise typer.Exit(1) from None
    _end_process()


def _end_process() -> None:
    """End the process once the hub has stopped, without the interpreter's teardown.

    Why: the hub's stop has written history, closed every connection and ended its child
    processes; what the teardown adds is the native libraries' own (onnxruntime, OpenCV, loaded by
    device plugins) destructors, and one of them aborted the process now and then ("terminate
    called without an active exception", exit -6; once in 30 stops of the demo under CPU load here):
    a clean stop reported as a crash. So the output is flushed, logging shut down, and the process
    exits 0 as the stop did."""
    import logging
    import os
    import sys

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(0)


def _warn_failed_plugins() -> None:
    """One line on stderr per installed plugin that could not be loaded (its families are missing)."""
    from wott_hub.plugins import get_registry

    for name, error in get_registry().failed_plugins().items():
        typer.echo(f"warning: plugin {name!r} not loaded: {error}", err=True)


def _retention(cfg: HubConfig) -> str:
    bounds = [f"{cfg.retention_mb:g} MB" if cfg.retention_mb else "",
              f"{cfg.retention_days:g} days" if cfg.retention_days else ""]
    said = " and ".join(b for b in bounds if b)
    return f"oldest deleted beyond {said}" if said else "kept for ever (no retention_mb/retention_days)"


def banner(hub: Hub, info: dict[str, Any], cfg: HubConfig) -> list[str]:
    """The lines ``run`` prints once the hub serves: URLs whole (never cut), a count of each list."""
    from wott_hub.history.db import describe

    what = "demo scene" if cfg.demo else cfg.source
    served, failed = info["devices"], info["failed"]
    lines = [f"wott-hub {cfg.name!r} running ({what})",
             f"  twin       {info['http']}/   (the fleet in 3D: open it in a browser)",
             f"  HTTP       {info['http']}   catalogue {info['catalogue']}"]
    if info["websocket"]:
        lines.append(f"  WebSocket  {info['websocket']}/<id>   (wotpy JSON-RPC)")
    lines.append(f"  hub Thing  {info['hub']}")
    if info.get("foxglove"):
        lines.append(f"  Foxglove   {info['foxglove']}   (Foxglove: Open connection, Foxglove WebSocket)")
    if info.get("directory"):
        lines.append(f"  directory  {info['directory']}things   (W3C WoT TDD: search, events)")
    if info["database"]:
        lines += [f"  history    {describe(info['database'])}", f"             {_retention(cfg)}"]
    else:
        lines.append("  history    off")
    if usb := info.get("usb"):
        said = f"adopting {', '.join(usb['adopt'])} when plugged in"
        lines.append(f"  USB        {said}" + (f"; NOT: {usb['error']}" if usb["error"] else ""))
    count = f"{len(served)} serving" + (f", {len(failed)} FAILED (retried)" if failed else "")
    lines.append(f"  devices: {count}")
    width = max((len(d) for d in [*served, *failed]), default=0)
    for did, url in served.items():
        lines.append(f"    {did:<{width}}  {hub.devices[did].family:<14} {url}")
    for did, err in failed.items():
        lines.append(f"    {did:<{width}}  FAILED: {err}")
    if served:
        first = next(iter(served.values()))
        lines += ["  a device's events, live (SSE; add -H 'Last-Event-ID: N' to resume after N):",
                  f"    curl -N -H 'Accept: text/event-stream' {first}/events"]
    lines.append(f"ready in {info['ready_s']:.2f} s; Ctrl-C to stop")
    return lines
