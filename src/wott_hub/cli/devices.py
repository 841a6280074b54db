"""``wott-hub devices``: manage the devices of a running hub, over HTTP, through its hub Thing.

Every command is a plain WoT client of the hub at ``--url`` (default
http://127.0.0.1:8080, or ``WOTT_HUB_URL``): ``list`` and ``health`` read the hub
Thing's ``devices`` and ``health`` properties; ``add``, ``remove`` and
``restart`` invoke its ``addDevice``, ``removeDevice`` and ``restartDevice``
actions. The other devices' streams are not interrupted (docs/devices.md). An
error the hub answers (problem+json) ends the command with one line and the exit
code of its meaning (``wott_hub.errors``: 2 bad input, 3 not found, 4 conflict,
5 a device that cannot be opened).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import typer

app = typer.Typer(help="Manage the devices of a running hub (list, add, remove, restart, health).",
                  short_help="Manage the devices of a running hub.", no_args_is_help=True,
                  rich_markup_mode=None)

DEFAULT_URL = "http://127.0.0.1:8080"

UrlOption = typer.Option(DEFAULT_URL, "--url", envvar="WOTT_HUB_URL", help="The running hub's HTTP URL.")
TokenOption = typer.Option(None, "--token", envvar="WOTT_HUB_TOKEN",
                           help="Bearer token (adding/removing needs the admin scope, restarting control).")

__all__ = ["app"]


def _hub(url: str) -> str:
    return f"{url.rstrip('/')}/wot/hub"


def _request(method: str, url: str, token: str | None, body: Any = None) -> Any:
    """The JSON answer; a problem+json is raised as the ``WottHubError`` of its status."""
    import httpx

    from wott_hub.errors import Conflict, DriverError, InvalidInput, NotFound, WottHubError

    headers = {"Authorization": f"Bearer {token}"} if token else {}
    try:
        r = httpx.request(method, url, json=body, headers=headers, timeout=60)
    except httpx.HTTPError as e:
        raise WottHubError(f"cannot reach the hub at {url}: {e}") from None
    if r.status_code < 400:
        return r.json()
    try:
        detail = r.json().get("detail") or r.reason_phrase
    except ValueError:
        detail = r.text.strip() or r.reason_phrase
    kinds = {400: InvalidInput, 404: NotFound, 409: Conflict, 422: DriverError}
    error = kinds.get(r.status_code, WottHubError)
    raise error(f"{detail} (HTTP {r.status_code})")


def _tables(text: str, source: str, only: str | None) -> list[dict[str, Any]]:
    """The device tables of a TOML text: its ``[[device]]`` tables, or the text itself as one table."""
    import tomllib

    from wott_hub.errors import InvalidInput, NotFound

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InvalidInput(f"{source}: not TOML: {e}") from None
    tables = data.get("device")
    if tables is None:
        tables = [data]
    elif not isinstance(tables, list):
        raise InvalidInput(f"{source}: 'device' must be an array of tables ([[device]])")
    if only is not None:
        tables = [t for t in tables if isinstance(t, dict) and t.get("id") == only]
        if not tables:
            raise NotFound(f"{source}: no device {only!r}")
    if not tables:
        raise InvalidInput(f"{source}: no device table (id, family and the family's settings)")
    return tables


@app.command("list", short_help="The hub's devices, their state and counters.")
def list_devices(url: str = UrlOption, token: str = TokenOption,
                 as_json: bool = typer.Option(False, "--json", help="Print the rows as JSON.")) -> None:
    """The hub's devices: id, family, state, frames, restarts, reason (failed ones included)."""
    devices = _request("GET", f"{_hub(url)}/properties/devices", token)
    health = _request("GET", f"{_hub(url)}/properties/health", token).get("devices", {})
    rows = []
    for d in devices:
        h = health.get(d["id"], {})
        rows.append({"id": d["id"], "family": d.get("family", ""),
                     "state": h.get("state", d.get("state", "")),
                     "frames": h.get("frames", ""), "restarts": h.get("restarts", ""),
                     "reason": h.get("reason", ""), "td": d.get("td", "")})
    listed = {r["id"] for r in rows}
    for did, h in health.items():
        if did not in listed:  # configured but not served: failed to open (retried) or removed meanwhile
            rows.append({"id": did, "family": "", "state": h.get("state", ""), "frames": "", "restarts": "",
                         "reason": h.get("reason", ""), "td": ""})
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    from ._table import Column, render

    columns = [Column("id", "id"), Column("family", "family", drop=2), Column("state", "state"),
               Column("frames", "frames", drop=1, align=">"),
               Column("restarts", "restarts", drop=3, align=">"),
               Column("reason", "reason", wrap=True), Column("TD", "td", drop=4)]
    typer.echo("\n".join(render(columns, rows)))


@app.command(short_help="Health and counters of the devices, as JSON.")
def health(device: str = typer.Argument(None, help="One device (default: all)."), url: str = UrlOption,
           token: str = TokenOption) -> None:
    """Health and counters of the devices (frames, frameErrors, restarts, tares, lastTare...), as JSON."""
    from wott_hub.errors import NotFound

    devices = _request("GET", f"{_hub(url)}/properties/health", token).get("devices", {})
    if device is not None:
        if device not in devices:
            raise NotFound(f"no device {device!r} on the hub at {url}")
        devices = devices[device]
    typer.echo(json.dumps(devices, indent=2))


@app.command()
def add(file: str = typer.Argument(..., help="A TOML file ('-': stdin) with [[device]] tables, like the "
                                             "hub's config, or one table: id, family and its settings."),
        device: str = typer.Option(None, "--id", help="Add only the [[device]] with this id."),
        url: str = UrlOption, token: str = TokenOption) -> None:
    """Open devices on the running hub and serve them (addDevice)."""
    from wott_hub.errors import InvalidInput

    if file == "-":
        text, source = sys.stdin.read(), "<stdin>"
    else:
        try:
            text, source = Path(file).read_text(), file
        except OSError as e:
            raise InvalidInput(f"{file}: {e.strerror or e}") from None
    for table in _tables(text, source, device):
        out = _request("POST", f"{_hub(url)}/actions/addDevice", token, table)
        typer.echo(f"added {out['id']}: {out['td']} ({out['state']}; actions: {', '.join(out['actions'])})")


@app.command()
def remove(device: str = typer.Argument(..., help="The device's id."), url: str = UrlOption,
           token: str = TokenOption) -> None:
    """Stop a device and stop serving it (removeDevice)."""
    _request("POST", f"{_hub(url)}/actions/removeDevice", token, {"id": device})
    typer.echo(f"removed {device}")


@app.command(short_help="Close a device's driver and open it again.")
def restart(device: str = typer.Argument(..., help="The device's id."), url: str = UrlOption,
            token: str = TokenOption) -> None:
    """Close a device's driver and open it again; its stream and subscribers stay (restartDevice)."""
    out = _request("POST", f"{_hub(url)}/actions/restartDevice", token, {"id": device})
    typer.echo(f"restarted {device}: {out['detail']}")
