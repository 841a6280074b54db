"""``wott-hub discover``: the WoT Things and directories announced on the local network.

Browses mDNS/DNS-SD (``_wot._tcp`` and ``_directory._sub._wot._tcp``) for a
few seconds, resolves each service and, unless ``--no-fetch``, fetches its TD
to show what it is.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import typer

app = typer.Typer(help="Browse mDNS for WoT Things and directories.", rich_markup_mode=None)

__all__ = ["app", "browse"]


async def browse(seconds: float, interfaces: list[str] | None, fetch: bool) -> list[dict[str, Any]]:
    from zeroconf.asyncio import AsyncZeroconf

    from wott_hub.discovery import Browser, Explorer, ServiceRecord, td_kind

    aiozc = AsyncZeroconf(interfaces=interfaces) if interfaces else AsyncZeroconf()
    found: dict[str, ServiceRecord] = {}

    def seen(rec: ServiceRecord) -> None:
        found[rec.name] = rec

    def gone(rec: ServiceRecord) -> None:
        found.pop(rec.name, None)

    browser = Browser(aiozc, seen, seen, gone)
    await browser.start()
    await asyncio.sleep(seconds)
    await browser.stop()
    rows = []
    explorer = Explorer(on_found=lambda f: None, claim=None, timeout=min(5.0, max(1.0, seconds)))
    for rec in sorted(found.values(), key=lambda r: (r.kind != "Directory", r.name)):
        row: dict[str, Any] = {"name": rec.instance, "type": rec.kind, "url": rec.url,
                               "addresses": list(rec.addresses), "port": rec.port, "txt": rec.properties}
        if fetch:
            try:
                td, url = await explorer.fetch_record(rec)
                row.update(url=url, id=td.get("id"), title=td.get("title"), td_type=td_kind(td))
            except OSError as e:
                row["error"] = str(e)
        rows.append(row)
    await explorer.close()
    await aiozc.async_close()
    return rows


@app.command(short_help="WoT Things and directories announced by mDNS.")
def discover(
    timeout: float = typer.Option(3.0, help="Seconds to listen for announcements."),
    interface: list[str] = typer.Option(None, help="Only this interface address (repeatable), "
                                        "e.g. 127.0.0.1; default: all."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
    fetch: bool = typer.Option(True, help="Fetch each TD to show its id and title."),
) -> None:
    """List the WoT Things and Thing Description Directories announced by mDNS/DNS-SD."""
    rows = asyncio.run(browse(timeout, interface or None, fetch))
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    if not rows:
        typer.echo(f"no WoT services announced within {timeout:g} s")
        return
    from ._table import Column, render

    shown = [{**r, "id": r.get("id") or r.get("error", ""), "title": r.get("title") or ""} for r in rows]
    columns = [Column("type", "type"), Column("TD URL", "url"), Column("name", "name", drop=2),
               Column("id", "id", drop=1), Column("title", "title", drop=3, wrap=True)]
    typer.echo("\n".join(render(columns, shown)))
