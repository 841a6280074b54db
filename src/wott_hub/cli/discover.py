"""``wott-hub discover``: the WoT Things and directories announced on the local network, or
(``--usb``) the USB devices the plugins know that are plugged in now.

Browses mDNS/DNS-SD (``_wot._tcp`` and ``_directory._sub._wot._tcp``) for a
few seconds, resolves each service and, unless ``--no-fetch``, fetches its TD
to show what it is. ``--usb`` reads udev instead (``wott_hub.discovery.usb``): one line per
device, with its family, USB id, serial number, node, the Thing id it would be served as and
whether a hub with ``--config``'s ``[usb] adopt`` would adopt it.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import typer

app = typer.Typer(help="Browse mDNS for WoT Things and directories.", rich_markup_mode=None)

__all__ = ["app", "browse", "usb_rows"]


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


def usb_rows(config: Path | None) -> list[dict[str, Any]]:
    """The USB devices present that a plugin's match claims, each with whether ``config``'s ``[usb]
    adopt`` would adopt it and why not; ``UdevUnavailable`` (one line) without udev."""
    from wott_hub.config import HubConfig
    from wott_hub.discovery.usb import scan
    from wott_hub.plugins import get_registry

    adopt = HubConfig.load(config).usb.adopt if config is not None else ()
    registry = get_registry()
    families = registry.families()
    rows = []
    for dev in scan(registry.usb_matches(), adopt):
        if not dev.adoptable:
            why = "listed only: its family is reached another way"
        elif dev.family not in families:
            why = f"family {dev.family!r} is not installed"
        elif dev.family not in adopt:
            why = "not in [usb] adopt" if config is not None else "not in [usb] adopt (no --config)"
        else:
            why = ""
        rows.append({**dev.to_dict(adopted=not why), "why_not": why})
    return rows


def _usb_line(row: dict[str, Any], width: int) -> str:
    """One device, one line: what it is (the label, in brackets) only where the terminal has room for
    it (no value is cut; --json has it all)."""
    adopted = "adopt: yes" if row["adopted"] else f"adopt: no ({row['why_not']})"
    also = f"; also {', '.join(row['also'])}?" if row["also"] else ""
    line = (f"{row['node']}  {row['family']}  {row['usb']}  serial {row['serial'] or '-'}  id {row['id']}  "
            f"{adopted}")
    full = f"{line}  [{row['label']}{also}]"
    return full if len(full) <= width else f"{line}  [also {', '.join(row['also'])}?]" if also else line


@app.command(short_help="WoT Things announced by mDNS; --usb: USB sensors.")
def discover(
    timeout: float = typer.Option(3.0, help="Seconds to listen for announcements."),
    interface: list[str] = typer.Option(None, help="Only this interface address (repeatable), "
                                        "e.g. 127.0.0.1; default: all."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
    fetch: bool = typer.Option(True, help="Fetch each TD to show its id and title."),
    usb: bool = typer.Option(False, "--usb", help="List the USB devices plugged in now that a plugin knows "
                             "(udev), one line each, instead of browsing mDNS."),
    config: Path = typer.Option(None, "--config", "-c", dir_okay=False, help="--usb: the hub config whose "
                                "[usb] adopt says which devices a hub would adopt."),
) -> None:
    """List the WoT Things and Thing Description Directories announced by mDNS/DNS-SD; with --usb, the
    USB devices plugged in now that a plugin knows, one line each."""
    if usb:
        found = usb_rows(config)
        if as_json:
            typer.echo(json.dumps(found, indent=2))
        elif not found:
            typer.echo("no known USB device is plugged in")
        else:
            from ._table import terminal_width

            width = terminal_width()
            typer.echo("\n".join(_usb_line(r, width) for r in found))
        return
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
