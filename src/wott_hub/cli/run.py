"""``wott-hub run``: the hub. No config: the demo scene on 127.0.0.1."""

from __future__ import annotations

import time
from pathlib import Path

import typer

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
) -> None:
    """Run the hub: one WoT servient for every device, SSE and WebSocket events, history.

    Ctrl-C or SIGTERM stops it cleanly: devices stop, streams end, queued events are written.
    """
    import asyncio
    import dataclasses
    import json
    import logging

    from wott_hub.config import ConfigError, HubConfig

    logging.basicConfig(level=log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        cfg = HubConfig.load(config) if config else HubConfig.demo_config()
    except ConfigError as e:
        typer.echo(f"error: {e}", err=True)
        raise typer.Exit(2) from None
    changes = {k: v for k, v in {"host": host, "http_port": port, "ws_port": ws_port,
                                 "database": database}.items() if v is not None}
    if no_history:
        changes["history"] = False
    cfg = dataclasses.replace(cfg, **changes)

    from wott_hub.hub import serve

    def ready(hub) -> None:
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
    except Exception as e:
        from wott_hub.history.db import HistoryError

        if isinstance(e, HistoryError):
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(1) from None
        raise


def _print(hub, info: dict, cfg) -> None:
    w = typer.echo
    what = "demo scene" if cfg.demo else cfg.source
    w(f"wott-hub {cfg.name!r} running ({what})")
    w(f"  HTTP       {info['http']}   catalogue {info['catalogue']}")
    if info["websocket"]:
        w(f"  WebSocket  {info['websocket']}/<id>   (wotpy JSON-RPC)")
    w(f"  hub Thing  {info['hub']}")
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
