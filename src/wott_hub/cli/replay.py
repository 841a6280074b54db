"""``wott-hub replay``: re-emit a recorded range as live events of a replay Thing."""

from __future__ import annotations

from pathlib import Path

import typer

from ._db import resolve_database, time_range

app = typer.Typer()


@app.command()
def replay(
    device: list[str] = typer.Option(..., "--device", help="Recorded device id (see `wott-hub history "
                                     "list`); repeatable: the devices replay together on one time base."),
    name: list[str] = typer.Option(None, "--name", help="Only these affordances (repeatable), e.g. "
                                   "skinDeformedDetection."),
    offset: float = typer.Option(0.0, "--offset", help="Start this many seconds into the range (seek)."),
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    t_to: str = typer.Option(None, "--to", help="End, same forms as --from."),
    speed: float = typer.Option(1.0, help="Time scale: 2 plays twice as fast; 0 as fast as possible."),
    loop: bool = typer.Option(False, "--loop", help="Start again after the end, until Ctrl-C."),
    delay: float = typer.Option(1.0, help="Seconds to wait before the first event (time to subscribe)."),
    linger: float = typer.Option(1.0, help="Seconds to keep serving after the last event."),
    host: str = typer.Option("127.0.0.1", help="Address to listen on."),
    port: int = typer.Option(8090, "--port", help="HTTP port of the replay server; 0 = any free port."),
    ws_port: int = typer.Option(8091, "--ws-port", help="WebSocket port (wotpy JSON-RPC); 0 = any free."),
    database: str = typer.Option(None, "--database", "-d", help="Database file or URL."),
    config: Path = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                                help="Hub config naming the database."),
    as_json: bool = typer.Option(False, "--json", help="Print the replay Thing's URLs as one JSON line."),
) -> None:
    """Serve a replay Thing ``replay-DEVICE`` per device (its TD) and re-emit the recorded events.

    Subscribers get the recorded payloads unchanged, in order, at the original
    pace divided by --speed, over SSE and WebSocket like a live device.
    """
    import asyncio
    import json
    import math
    import signal

    from wott_hub.config import HubConfig
    from wott_hub.errors import InvalidInput, WottHubError
    from wott_hub.history.db import open_existing
    from wott_hub.hub import Hub
    from wott_hub.network import DirectoryConfig

    lo, hi = time_range(t_from, t_to)
    for opt, value in (("--speed", speed), ("--delay", delay), ("--linger", linger), ("--offset", offset)):
        if not (math.isfinite(value) and value >= 0):
            raise InvalidInput(f"{opt} must be a finite number >= 0, got {value}")
    db = resolve_database(database, config)
    open_existing(db).dispose()  # exists, is a history database this wott-hub reads, not corrupted
    # no directory: the one in this database belongs to the hub that runs on it (one owner per tables)
    devices = list(dict.fromkeys(device))
    cfg = HubConfig(name=f"replay of {', '.join(devices)}", host=host, http_port=port, ws_port=ws_port,
                    database=db,
                    directory=DirectoryConfig(enabled=False))

    async def main() -> int:
        hub = Hub(cfg)
        stop = asyncio.Event()
        loop_ = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop_.add_signal_handler(sig, stop.set)
        await hub.start()
        try:
            rt = await hub.add_replay(devices[0], t_from_ns=lo, t_to_ns=hi, speed=speed, loop=loop,
                                      names=name or None, offset_s=offset, with_devices=devices[1:])
        except WottHubError:  # no such recorded device: reported by the CLI, once the hub is down
            await hub.stop()
            raise
        url = hub.td_url(rt.id)
        if as_json:
            typer.echo(json.dumps({"thing": rt.id, "td": url, "events": f"{url}/events",
                                   "websocket": hub.ws_url, "speed": speed, "loop": loop,
                                   "things": {g.id: hub.td_url(g.id) for g in rt.group}}))
        else:
            for g in rt.group:
                typer.echo(f"replaying {g.source!r} as {g.id!r} at {speed:g}x{' (loop)' if loop else ''}")
                typer.echo(f"  TD   {hub.td_url(g.id)}")
                typer.echo(f"  SSE  {hub.td_url(g.id)}/events")
        try:
            await asyncio.wait_for(stop.wait(), delay)
        except TimeoutError:
            task = hub.start_replay(rt)
            waiter = asyncio.ensure_future(stop.wait())
            await asyncio.wait({task, waiter}, return_when=asyncio.FIRST_COMPLETED)
            if task.done() and not stop.is_set():
                typer.echo(f"replayed {rt.replayer.emitted} records", err=True)
                try:
                    await asyncio.wait_for(stop.wait(), linger)
                except TimeoutError:
                    pass
            waiter.cancel()
        await hub.stop()
        return 0

    code = asyncio.run(main())
    raise typer.Exit(code)
