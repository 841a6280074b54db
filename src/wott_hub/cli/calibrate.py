"""``wott-hub calibrate``: calibrate a device family from recorded data, through its plugin.

The plugin that provides the family does the work (``wott_hub_calibrate``, docs/plugins.md); this
command names the data, the output and the family's options (``--option KEY=VALUE``, repeated) and
prints the plugin's one-line summary. The gel families take ball presses (docs/gel.md).
"""

from __future__ import annotations

import typer

__all__ = ["app"]

app = typer.Typer(rich_markup_mode=None)


@app.command("calibrate", short_help="Calibrate a device family from recorded data (its plugin's method).")
def calibrate(
    family: str = typer.Argument(..., help="The device family, e.g. gelsight-mini (see plugins families)."),
    data: str = typer.Argument(..., help="The recorded data, in the format the family documents."),
    out: str = typer.Option(..., "--out", "-o", help="Where to write the calibration."),
    option: list[str] = typer.Option([], "--option", help="KEY=VALUE, the family's options (repeat it)."),
) -> None:
    """Calibrate FAMILY from DATA into --out, e.g. the gel sensors' depth from ball presses:

    wott-hub calibrate gelsight-mini presses.npz -o mini-depth.npz --option ball_diameter_mm=4

    Exit codes: 2 an option, the data or the family refused (one line saying which).
    """
    from wott_hub.errors import SettingsError
    from wott_hub.plugins import get_registry

    options: dict[str, str] = {}
    for pair in option:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise SettingsError(f"--option: expected KEY=VALUE, got {pair!r}")
        options[key.strip()] = value.strip()
    typer.echo(get_registry().calibrate(family, data, out, options))
