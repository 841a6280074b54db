"""``wott-hub config check``: read a hub config as ``run`` would, report every problem at once, serve
nothing.

Why a command of its own: a hub takes many seconds to start, and one that starts with a
misspelt setting marks the device failed and keeps running; a person fixing a config wants
every mistake listed, each with its file, table and key, before anything starts. Exit
codes by class (``wott_hub.errors.EXIT_CODES``): 0 all good; 2 a config error (a table, a
key, a value, a device's settings, the database URL's scheme, a file ``[security]`` names);
5 a device that does not open (``--open`` only: the settings are right, the device is not
there).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

if TYPE_CHECKING:
    from wott_hub.config import HubConfig

    from ._check import DeviceCheck

__all__ = ["app", "check", "load_checked"]

app = typer.Typer(help="Check a hub config without starting the hub.", no_args_is_help=True,
                  rich_markup_mode=None)


def load_checked(config: Path | None) -> tuple[HubConfig, list[DeviceCheck], list[str]]:
    """The config (the demo's without a file), each device's check, and every problem found, one
    line each; a ``ConfigError`` (every line of it) when the file's tables are wrong already."""
    from wott_hub.config import HubConfig

    from ._check import check_devices, check_files, check_usb

    cfg = HubConfig.load(config) if config is not None else HubConfig.demo_config()
    if cfg.demo and not cfg.devices:
        from dataclasses import replace

        from wott_hub.plugins.demo import demo_devices

        cfg = replace(cfg, devices=tuple(demo_devices()))
    devices = check_devices(cfg)
    problems = [*check_files(cfg), *check_usb(cfg), *(line for d in devices for line in d.errors)]
    return cfg, devices, problems


@app.command(short_help="Every problem of a config; nothing is started.")
def check(
    config: Path = typer.Option(None, "--config", "-c", dir_okay=False,
                                help="Hub config (TOML). Without it: the demo fleet."),
    open_: bool = typer.Option(False, "--open", help="Also open each device through its plugin (serial "
                               "ports, cameras, model files), read its first frame and close it again; "
                               "nothing is served."),
    wait: float = typer.Option(10.0, "--wait", min=0.1, max=600, help="--open: seconds a device has to give "
                               "its first frame."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON for scripts."),
) -> None:
    """Read the config as 'wott-hub run' would and list every problem: tables, keys, values, each
    device's family and settings, the database URL, the [security] files; exit 0 when the hub
    would start.

    Exit codes: 2 a config error, 5 a device that does not open (--open).
    """
    from wott_hub.errors import ConfigError

    try:
        cfg, devices, problems = load_checked(config)
    except ConfigError as e:
        if not as_json:
            raise
        typer.echo(json.dumps({"ok": False, "errors": str(e).splitlines(), "devices": []}, indent=2))
        raise typer.Exit(2) from None
    if open_ and not problems:
        import asyncio

        from ._check import open_devices

        asyncio.run(open_devices(devices, cfg, frame_s=wait))
    failed = [d for d in devices if d.open_error]
    code = 2 if problems else 5 if failed else 0
    if as_json:
        out: dict[str, Any] = {"ok": code == 0, "source": cfg.source, "errors": problems,
                               "devices": [d.to_dict() for d in devices]}
        typer.echo(json.dumps(out, indent=2))
        raise typer.Exit(code)
    for line in problems:
        typer.echo(f"error: {line}", err=True)
    for d in failed:
        typer.echo(f"error: {d.where}: {d.open_error}", err=True)
    for d in devices:
        if d.opened:
            typer.echo(f"opened {d.id} ({d.family}): {d.opened}; closed")
    what = "the demo fleet" if config is None else cfg.source
    if config is not None and cfg.demo:
        what += " (no [[device]]: the demo fleet)"
    summary = f"{what}: {len(devices)} device(s)"
    if cfg.usb.adopt:  # docs/usb.md
        summary += f" and USB {', '.join(cfg.usb.adopt)} when plugged in"
    if code == 0:
        typer.echo(f"{summary}: OK{' (each opened and closed)' if open_ else ''}")
    else:
        typer.echo(f"{summary}: {len(problems)} config error(s), {len(failed)} device(s) not opening",
                   err=True)
    raise typer.Exit(code)
