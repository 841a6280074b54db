"""The ``wott-hub`` command. Each command group lives in its own module here and
imports its heavy dependencies inside the commands, so ``--help`` stays fast.

Contract: every error a person can cause ends a command with one line per problem on
stderr (``error: ...``) and an exit code, never a traceback: the hub's own errors
(``wott_hub.errors``, exit code by class: ``errors.EXIT_CODES``), a mistyped option or
value (exit 2, the line names the option and the command's ``--help``), and a file or
device the system refuses (``OSError``: a full disk, a folder that cannot be made; exit
1). A config with several problems gives one line each. Help is plain text (no rich
markup: ``[[device]]`` in a help text stays ``[[device]]``).
"""

from __future__ import annotations

import errno
from typing import TYPE_CHECKING, Any

import typer
from typer.core import TyperGroup

if TYPE_CHECKING:
    from typer import _click  # typer vendors click: TyperGroup.invoke takes its (unexported) Context

from . import (
    bench,
    calibrate,
    config,
    devices,
    directory,
    discover,
    episode,
    history,
    plugins,
    replay,
    run,
    td,
    tokens,
)

__all__ = ["app", "main"]


def _say(message: str) -> None:
    for line in message.splitlines() or [""]:
        typer.echo(f"error: {line}", err=True)


def _usage(e: Any) -> typer.Exit:
    """A mistyped option or value as one line naming the command's help (click prints four)."""
    text = e.format_message().strip().replace("Value error, ", "")  # pydantic's words, through typer
    text = text[:1].lower() + text[1:] if text[1:2].islower() else text
    where = f" (see {e.ctx.command_path} --help)" if e.ctx is not None else ""
    _say(f"{text}{where}")
    return typer.Exit(e.exit_code)


class _Commands(TyperGroup):
    """Every command runs inside ``invoke`` here: an error the hub reports on purpose
    (``wott_hub.errors``) ends it with one line on stderr and its exit code, in this one place
    for every command (``main`` and ``typer.testing.CliRunner`` alike); anything else is a bug
    and keeps its traceback."""

    def make_context(self, info_name: str | None, args: list[str], parent: _click.Context | None = None,
                     **extra: Any) -> _click.Context:
        from typer._click.exceptions import NoArgsIsHelpError, UsageError

        try:
            return super().make_context(info_name, args, parent, **extra)
        except NoArgsIsHelpError:
            raise
        except UsageError as e:
            raise _usage(e) from None

    def invoke(self, ctx: _click.Context) -> object:
        from typer._click.exceptions import NoArgsIsHelpError, UsageError

        from wott_hub.errors import WottHubError, exit_code

        try:
            return super().invoke(ctx)
        except WottHubError as e:
            _say(str(e))
            raise typer.Exit(exit_code(e)) from None
        except NoArgsIsHelpError:
            raise
        except UsageError as e:
            raise _usage(e) from None
        except OSError as e:
            if e.errno in (None, errno.EPIPE):  # a reader that went away: typer ends quietly
                raise
            where = f"{e.filename}: " if e.filename else ""
            _say(f"{where}{e.strerror or e}")
            raise typer.Exit(1) from None


app = typer.Typer(
    cls=_Commands,
    name="wott-hub",
    help="A gateway for fleets of tactile sensors (W3C Web of Things).",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)
app.add_typer(td.app, name="td")
app.add_typer(directory.app, name="directory")
app.add_typer(devices.app, name="devices")
app.registered_commands += discover.app.registered_commands
app.add_typer(plugins.app, name="plugins")
app.registered_commands += bench.app.registered_commands
app.registered_commands += calibrate.app.registered_commands
app.registered_commands += run.app.registered_commands
app.add_typer(config.app, name="config")
app.add_typer(history.app, name="history")
app.add_typer(episode.app, name="episode")
app.add_typer(tokens.app, name="tokens")
app.add_typer(tokens.tls_app, name="tls")
app.registered_commands += replay.app.registered_commands


def main() -> None:
    """``wott-hub``."""
    app()
