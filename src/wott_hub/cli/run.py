"""``wott-hub run``: the hub. No config: the demo scene on 127.0.0.1."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

if TYPE_CHECKING:
    from wott_hub.config import HubConfig
    from wott_hub.hub import Hub

_T0 = time.monotonic()

app = typer.Typer()


@app.command()
def run(
    config: Path = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                                help="Hub config (TOML, see docs/hub.md). Without it: the demo scene."),
    host: str = typer.Option(None, help="Address to listen on (default: config, else 127.0.0.1)."),
    port: int = typer.Option(None, "--port", help="HTTP port (TDs, properties, SSE); 0 = any free port."),
    ws_port: int = typer.Option(None, "--ws-port", help="WebSocket port (wotpy JSON-RPC); 0 = any free."),
    database: str = typer.Option(None, help="History database: a file (SQLite) or an SQLAlchemy URL."),
    no_history: bool = typer.Option(False, "--no-history", help="Do not record events."),
    as_json: bool = typer.Option(False, "--json", help="Print where everything is as one JSON line."),
    log_level: str = typer.Option("warning", help="Logging level (debug, info, warning, error)."),
    tokens: Path = typer.Option(None, "--tokens", dir_okay=False,
                                help="File of hashed tokens (wott-hub tokens create --file); default: "
                                     "[security] tokens_file."),
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

    Ctrl-C or SIGTERM stops it cleanly: devices stop, streams end, queued events are written.
    """
    import asyncio
    import dataclasses
    import json
    import logging

    from wott_hub.config import HubConfig, check_port

    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # a ConfigError (or a HistoryError when the hub starts) is reported by ``cli.main``: one line
    check_port(port, "--port"), check_port(ws_port, "--ws-port")  # 70000 would wrap to 4464
    check_port(foxglove_port, "--foxglove-port")
    cfg = HubConfig.load(config) if config else HubConfig.demo_config()
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

    from wott_hub.hub import serve

    _warn_failed_plugins()

    def ready(hub: Hub) -> None:
        info = hub.describe()
        info["ready_s"] = round(time.monotonic() - _T0, 3)
        if as_json:
            typer.echo(json.dumps(info), nl=True)
        else:
            _print(hub, info, cfg)

    try:
        asyncio.run(serve(cfg, ready=ready))
    except OSError as e:  # typically a port in use
        typer.echo(f"error: {e} (choose other ports with --port/--ws-port or in [hub])", err=True)
        raise typer.Exit(1) from None


def _warn_failed_plugins() -> None:
    """One line on stderr per installed plugin that could not be loaded (its families are missing)."""
    from wott_hub.plugins import get_registry

    for name, error in get_registry().failed_plugins().items():
        typer.echo(f"warning: plugin {name!r} not loaded: {error}", err=True)


def _print(hub: Hub, info: dict[str, Any], cfg: HubConfig) -> None:
    w = typer.echo
    what = "demo scene" if cfg.demo else cfg.source
    w(f"wott-hub {cfg.name!r} running ({what})")
    w(f"  HTTP       {info['http']}   catalogue {info['catalogue']}")
    if info["websocket"]:
        w(f"  WebSocket  {info['websocket']}/<id>   (wotpy JSON-RPC)")
    w(f"  hub Thing  {info['hub']}")
    if info.get("foxglove"):
        w(f"  Foxglove   {info['foxglove']}   (Foxglove: Open connection, Foxglove WebSocket)")
    if info.get("directory"):
        w(f"  directory  {info['directory']}things   (W3C WoT TDD: search/jsonpath, events)")
    w(f"  history    {info['database'] or 'off'}")
    w(f"  devices ({len(info['devices'])}):")
    for did, url in info["devices"].items():
        dev = hub.devices[did]
        w(f"    {did:<16} {dev.family:<16} {url}")
        w(f"    {'':<16} {'':<16} SSE {url}/events   (Last-Event-ID resumes)")
    for did, err in info["failed"].items():
        w(f"    {did:<16} FAILED: {err}")
    w(f"ready in {info['ready_s']:.2f} s; Ctrl-C to stop")
