"""The ``wott-hub`` command. Each command group lives in its own module here and
imports its heavy dependencies inside the commands, so ``--help`` stays fast."""

from __future__ import annotations

import typer

from . import bench, td

app = typer.Typer(
    name="wott-hub",
    help="A gateway for fleets of tactile sensors (W3C Web of Things).",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(td.app, name="td")
app.registered_commands += bench.app.registered_commands


def main() -> None:
    app()
