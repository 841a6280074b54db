"""The ``wott-hub`` command. Each command group lives in its own module here and
imports its heavy dependencies inside the commands, so ``--help`` stays fast."""

from __future__ import annotations

import typer

from . import bench, directory, discover, history, plugins, replay, run, td

app = typer.Typer(
    name="wott-hub",
    help="A gateway for fleets of tactile sensors (W3C Web of Things).",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(td.app, name="td")
app.add_typer(directory.app, name="directory")
app.registered_commands += discover.app.registered_commands
app.add_typer(plugins.app, name="plugins")
app.registered_commands += bench.app.registered_commands
app.registered_commands += run.app.registered_commands
app.add_typer(history.app, name="history")
app.registered_commands += replay.app.registered_commands


def main() -> None:
    app()
