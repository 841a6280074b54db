"""``wott-hub plugins``: what driver plugins are installed, what they provide, what failed.

``families`` lists the device families, one line each; ``families NAME`` prints one family's
settings (nested tables flattened, as docs/configuration.md shows the first-party ones:
``wott_hub.config_docs.settings_rows``) and its rules across settings.
"""

from __future__ import annotations

import json

import typer

__all__ = ["app"]

app = typer.Typer(help="Installed driver plugins and the device families they provide.", no_args_is_help=True,
                  rich_markup_mode=None)


@app.command("list", short_help="Every driver plugin, and why one failed.")
def list_plugins(
    as_json: bool = typer.Option(False, "--json", help="Print JSON (a list of plugins) for scripts."),
) -> None:
    """Every driver plugin: distribution, version, families, hooks, and the error of any that failed.

    Set WOTT_HUB_PLUGINS=name,name to load only those plugins.
    """
    from wott_hub.plugins import get_registry

    from ._table import Column, render

    plugins = get_registry().plugins()
    if as_json:
        typer.echo(json.dumps([p.to_dict() for p in plugins], indent=2))
        return
    rows = [{"plugin": p.name, "distribution": p.distribution or "-", "version": p.version or "-",
             "families": "\n".join(p.families) or "-",
             "hooks": "\n".join(h.removeprefix("wott_hub_") for h in p.hooks) or "-",
             "error": p.error or ""} for p in plugins]
    columns = [Column("plugin", "plugin"), Column("distribution", "distribution", drop=1),
               Column("version", "version", drop=2), Column("families", "families"),
               Column("hooks", "hooks", drop=3), Column("error", "error", wrap=True)]
    if not any(p.error for p in plugins):
        columns.pop()
    typer.echo("\n".join(render(columns, rows, title="wott-hub driver plugins")))
    failed = [p.name for p in plugins if p.error]
    if failed:
        typer.echo(f"{len(failed)} plugin(s) with errors: {', '.join(failed)}", err=True)


@app.command(short_help="Device families, or one family's settings.")
def families(
    name: str = typer.Argument(None, help="One family: its settings. Omit to list the families."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON (families with their settings schema)."),
) -> None:
    """The device families, or the settings a [[device]] table of family NAME takes."""
    from wott_hub.errors import NotFound
    from wott_hub.plugins import get_registry

    from ._table import Column, render

    fams = get_registry().families()
    if name is not None:
        if name not in fams:
            from wott_hub.configspec import suggest

            raise NotFound(f"no family {name!r}{suggest(name, fams)} (installed: {', '.join(sorted(fams))})")
        fams = {name: fams[name]}
    if as_json:
        typer.echo(json.dumps([f.to_dict() for f in fams.values()], indent=2))
        return
    if name is None:
        rows = [{"family": f.name, "plugin": f.plugin, "description": f.description}
                for f in sorted(fams.values(), key=lambda f: f.name)]
        columns = [Column("family", "family"), Column("plugin", "plugin"),
                   Column("description", "description", wrap=True)]
        typer.echo("\n".join(render(columns, rows)))
        typer.echo("\nthe settings of one: wott-hub plugins families NAME")
        return
    import textwrap

    from wott_hub.config_docs import family_rules, settings_rows

    from ._table import terminal_width

    fam = fams[name]
    assert isinstance(fam.schema, dict)  # the registry turns a settings model into its JSON Schema
    head = f"family {fam.name!r} (plugin {fam.plugin}): {fam.description}"
    typer.echo(textwrap.fill(head, terminal_width(), break_long_words=False, break_on_hyphens=False))
    for rule in family_rules(fam.schema):
        typer.echo(f"rule: {rule.replace('`', '')}")
    rows = [{"setting": r.key, "default": r.default, "meaning": r.meaning,
             "type": f"{r.type.replace(' or ', ' | ')}{', ' + _tight(r.bounds) if r.bounds else ''}"}
            for r in settings_rows(fam.schema)]
    columns = [Column("setting", "setting"), Column("default", "default"),
               Column("type, bounds", "type", wrap=True, most=22), Column("meaning", "meaning", wrap=True)]
    typer.echo("\n".join(render(columns, rows)))


def _tight(bounds: str) -> str:
    """``≥ 1, ≤ 12000000`` as ``≥1, ≤12000000``: a bound wraps as one word."""
    for sign in "≥≤><":
        bounds = bounds.replace(f"{sign} ", sign)
    return bounds
