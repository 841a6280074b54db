"""``wott-hub plugins``: what driver plugins are installed, what they provide, what failed."""

from __future__ import annotations

import json

import typer

app = typer.Typer(help="Installed driver plugins and the device families they provide.", no_args_is_help=True)


@app.command("list")
def list_plugins(
    as_json: bool = typer.Option(False, "--json", help="Print JSON (a list of plugins) for scripts."),
) -> None:
    """Every driver plugin: distribution, version, families, hooks, and the error of any that failed.

    Set WOTT_HUB_PLUGINS=name,name to load only those plugins.
    """
    from wott_hub.plugins import get_registry

    plugins = get_registry().plugins()
    if as_json:
        typer.echo(json.dumps([p.to_dict() for p in plugins], indent=2))
        return
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    table = Table(title="wott-hub driver plugins")
    for col in ("plugin", "distribution", "version", "families", "hooks", "error"):
        table.add_column(col, overflow="fold", style="red" if col == "error" else None)
    for p in plugins:
        table.add_row(*map(escape, (
            p.name, p.distribution or "-", p.version or "-", "\n".join(p.families) or "-",
            "\n".join(h.removeprefix("wott_hub_") for h in p.hooks) or "-", p.error or "",
        )))
    Console().print(table)
    failed = [p.name for p in plugins if p.error]
    if failed:
        Console(stderr=True).print(f"{len(failed)} plugin(s) with errors: {escape(', '.join(failed))}",
                                   style="red")


@app.command()
def families(
    as_json: bool = typer.Option(False, "--json", help="Print JSON (families with their settings schema)."),
) -> None:
    """Every device family and the settings a [[device]] table of that family takes."""
    from wott_hub.plugins import get_registry

    fams = get_registry().families()
    if as_json:
        typer.echo(json.dumps([f.to_dict() for f in fams.values()], indent=2))
        return
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console()
    for fam in sorted(fams.values(), key=lambda f: f.name):
        props = fam.schema.get("properties") or {}
        required = set(fam.schema.get("required") or ())
        table = Table(title=escape(f"family {fam.name!r} (plugin {fam.plugin}): {fam.description}"),
                      title_justify="left")
        for col in ("setting", "type", "default", "description"):
            table.add_column(col, overflow="fold")
        for key, prop in props.items():
            kind = prop.get("type") or (" | ".join(map(str, prop["enum"])) if "enum" in prop else "")
            default = json.dumps(prop["default"]) if "default" in prop else ""
            if key in required:
                default = "required"
            table.add_row(*map(escape, (key, str(kind), default, prop.get("description", ""))))
        console.print(table)
