"""The ``wott-hub`` command. Each command group lives in its own module here and
imports its heavy dependencies inside the commands, so ``--help`` stays fast."""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer
from typer.core import TyperGroup

if TYPE_CHECKING:
    from typer import _click  # typer vendors click: TyperGroup.invoke takes its (unexported) Context

from . import bench, devices, directory, discover, history, plugins, replay, run, td, tokens


class _Commands(TyperGroup):
    """Every command runs inside ``invoke`` here: an error the hub reports on purpose
    (``wott_hub.errors``) ends it with one line on stderr and its exit code, in this one place
    for every command (``main`` and ``typer.testing.CliRunner`` alike); anything else is a bug
    and keeps its traceback."""

    def invoke(self, ctx: _click.Context) -> object:
        from wott_hub.errors import WottHubError, exit_code

        try:
            return super().invoke(ctx)
        except WottHubError as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(exit_code(e)) from None


app = typer.Typer(
    cls=_Commands,
    name="wott-hub",
    help="A gateway for fleets of tactile sensors (W3C Web of Things).",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
app.add_typer(td.app, name="td")
app.add_typer(directory.app, name="directory")
app.add_typer(devices.app, name="devices")
app.registered_commands += discover.app.registered_commands
app.add_typer(plugins.app, name="plugins")
app.registered_commands += bench.app.registered_commands
app.registered_commands += run.app.registered_commands
app.add_typer(history.app, name="history")
app.add_typer(tokens.app, name="tokens")
app.add_typer(tokens.tls_app, name="tls")
app.registered_commands += replay.app.registered_commands


def main() -> None:
    """``wott-hub``."""
    app()
