"""``wott-hub replay``: re-emit a recorded range as live events of a replay Thing.

It starts at once (``--delay 0``): a subscriber that comes later asks for the replay from
its first record with ``Last-Event-ID: 0`` (the replay Thing keeps its last ``ring_size``
records for that, as a live device does). The database is not checked page by page first
(a replay reads only its range; a damaged page it meets is an error), and the replay
server records nothing: the command's start is the servient's, plus the range's first
page. On a terminal, stderr shows what it is doing while it starts and a bar while it plays.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from ._db import resolve_database, time_range

__all__ = ["app", "replay"]

app = typer.Typer(rich_markup_mode=None)


@app.command(short_help="Re-emit recorded devices as live replay Things.")
def replay(
    device: list[str] = typer.Option(..., "--device", help="Recorded device id (see wott-hub history "
                                     "list); repeatable: the devices replay together on one time base."),
    name: list[str] = typer.Option(None, "--name", help="Only these affordances (repeatable), e.g. "
                                   "skinDeformedDetection."),
    offset: float = typer.Option(0.0, "--offset", help="Start this many seconds into the range (seek)."),
    t_from: str = typer.Option(None, "--from", help="Start: ISO 8601 (local unless Z), -10m, seconds."),
    t_to: str = typer.Option(None, "--to", help="End, same forms as --from."),
    speed: float = typer.Option(1.0, help="Time scale: 2 plays twice as fast; 0 as fast as possible."),
    loop: bool = typer.Option(False, "--loop", help="Start again after the end, until Ctrl-C."),
    delay: float = typer.Option(0.0, help="Seconds to wait before the first event (a subscriber may "
                                "instead resume from the first with Last-Event-ID: 0)."),
    linger: float = typer.Option(1.0, help="Seconds to keep serving after the last event."),
    host: str = typer.Option("127.0.0.1", help="Address to listen on."),
    port: int = typer.Option(8090, "--port", help="HTTP port of the replay server; 0 = any free port."),
    ws_port: int = typer.Option(8091, "--ws-port", help="WebSocket port (wotpy JSON-RPC); 0 = any free."),
    database: str = typer.Option(None, "--database", "-d", help="Database file or URL."),
    config: Path = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                                help="Hub config naming the database."),
    as_json: bool = typer.Option(False, "--json", help="Print the replay Thing's URLs as one JSON line."),
    progress: bool = typer.Option(True, "--progress/--no-progress",
                                  help="What it is doing, and a bar, on stderr (a terminal only)."),
) -> None:
    """Serve a replay Thing 'replay-DEVICE' per device (its TD) and re-emit the recorded events.

    Subscribers get the recorded payloads unchanged, in order, at the original
    pace divided by --speed, over SSE and WebSocket like a live device.
    """
    import math

    from wott_hub.errors import InvalidInput

    from ._progress import wanted

    lo, hi = time_range(t_from, t_to)
    for opt, value in (("--speed", speed), ("--delay", delay), ("--linger", linger), ("--offset", offset)):
        if not (math.isfinite(value) and value >= 0):
            raise InvalidInput(f"{opt} must be a finite number >= 0, got {value}")
    shown = wanted(progress)
    status = _Status(shown)
    with status:
        status.say("opening the history database")
        db = resolve_database(database, config)
        from wott_hub.history.db import open_existing

        # exists, is a history database this wott-hub reads (never created or migrated here)
        open_existing(db, integrity=False).dispose()
        status.say("starting the replay server")
        code = _serve(db, list(dict.fromkeys(device)), lo, hi, name or None, offset, speed, loop, delay,
                      linger, host, port, ws_port, as_json, status)
    raise typer.Exit(code)


class _Status:
    """A line on stderr saying what the command is doing, while it starts (a terminal only)."""

    def __init__(self, shown: bool) -> None:
        self.shown = shown
        self._status = None
        if shown:
            from rich.console import Console

            self._status = Console(stderr=True).status("replay")

    def __enter__(self) -> _Status:
        if self._status is not None:
            self._status.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.done()

    def say(self, what: str) -> None:
        if self._status is not None:
            self._status.update(f"replay: {what}")

    def done(self) -> None:
        if self._status is not None:
            self._status.stop()
            self._status = None


def _serve(db: str, devices: list[str], lo: int | None, hi: int | None, names: list[str] | None,
           offset: float, speed: float, loop: bool, delay: float, linger: float, host: str, port: int,
           ws_port: int, as_json: bool, status: _Status) -> int:
    import asyncio
    import json
    import signal

    from wott_hub.config import HubConfig
    from wott_hub.errors import WottHubError
    from wott_hub.hub import Hub
    from wott_hub.network import DirectoryConfig

    from ._progress import Bar, Tracked

    # no directory: the one in this database belongs to the hub that runs on it (one owner per
    # tables); history in this process's thread: a replay records nothing
    cfg = HubConfig(name=f"replay of {', '.join(devices)}", host=host, http_port=port, ws_port=ws_port,
                    database=db, history_process=False, directory=DirectoryConfig(enabled=False))

    async def main() -> int:
        hub = Hub(cfg)
        stop = asyncio.Event()
        loop_ = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop_.add_signal_handler(sig, stop.set)
        await hub.start()
        status.say("reading the range's first records")
        try:
            rt = await hub.add_replay(devices[0], t_from_ns=lo, t_to_ns=hi, speed=speed, loop=loop,
                                      names=names, offset_s=offset, with_devices=devices[1:])
        except WottHubError:  # no such recorded device: reported by the CLI, once the hub is down
            await hub.stop()
            raise
        url = hub.td_url(rt.id)
        status.done()
        if as_json:
            typer.echo(json.dumps({"thing": rt.id, "td": url, "events": f"{url}/events",
                                   "websocket": hub.ws_url, "speed": speed, "loop": loop,
                                   "things": {g.id: hub.td_url(g.id) for g in rt.group}}))
        else:
            for g in rt.group:
                typer.echo(f"replaying {g.source!r} as {g.id!r} at {speed:g}x{' (loop)' if loop else ''}")
                typer.echo(f"  TD   {hub.td_url(g.id)}")
                typer.echo(f"  SSE  {hub.td_url(g.id)}/events")
            typer.echo(f"every record from the first: curl -N -H 'Accept: text/event-stream' "
                       f"-H 'Last-Event-ID: 0' {url}/events")
        total = 0
        if status.shown and not loop:  # the bar: records emitted of the range's (names filter aside)
            reader: Any = rt.replayer.reader  # the hub's HistoryReader
            spans = await asyncio.to_thread(Tracked.spans, reader, rt.replayer.things, lo, hi)
            total = Tracked.total(spans)
        try:
            await asyncio.wait_for(stop.wait(), delay)
        except TimeoutError:
            with Bar("replay", total, total > 0) as bar:
                task = hub.start_replay(rt)
                waiter = asyncio.ensure_future(stop.wait())
                while not (task.done() or stop.is_set()):
                    await asyncio.wait({task, waiter}, timeout=0.25, return_when=asyncio.FIRST_COMPLETED)
                    bar.update(rt.replayer.emitted)
            if task.done() and not stop.is_set():
                typer.echo(f"replayed {rt.replayer.emitted} records", err=True)
                try:
                    await asyncio.wait_for(stop.wait(), linger)
                except TimeoutError:
                    pass
            waiter.cancel()
        await hub.stop()
        return 0

    return asyncio.run(main())
