"""``wott-hub tokens``: create, list and revoke the hub's bearer tokens; ``wott-hub tls selfsigned``:
a certificate and key for a lab (docs/security.md).

A token is printed once, when it is created; what is stored (in a token file, or in
the ``[[security.client]]`` lines printed to paste into the config) is its scrypt hash.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from wott_hub.security.tokens import StoredToken

__all__ = ["app", "tls_app"]

app = typer.Typer(help="Bearer tokens with a scope (read, control, admin) for the hub's clients.",
                  short_help="Bearer tokens for the hub's clients.", no_args_is_help=True,
                  rich_markup_mode=None)
tls_app = typer.Typer(help="TLS certificates for https/wss.", no_args_is_help=True, rich_markup_mode=None)

_FILE = typer.Option(None, "--file", "-f", dir_okay=False,
                     help="Token file (JSON of hashed tokens; the hub reads it as [security] tokens_file "
                          "or run --tokens).")
_CONFIG = typer.Option(None, "--config", "-c", exists=True, dir_okay=False,
                       help="Hub config: its [security] tokens_file and [[security.client]] entries.")


@app.command()
def create(name: str = typer.Argument(..., help="Who holds it (shown in the audit trail)."),
           scope: str = typer.Option("read", "--scope", "-s", help="read, control or admin."),
           file: Path = _FILE) -> None:
    """Create a token and print it (once). With --file it is added to that file (the hub re-reads
    it, no restart); without, the [[security.client]] lines to paste into the config are printed."""
    from wott_hub.errors import InvalidInput
    from wott_hub.security import Scope, TokenFile, new_token

    level = Scope.parse(scope)
    if file is not None:
        try:
            token, stored = TokenFile(file).create(name, level)
        except OSError as e:  # a folder that cannot be made or written (/proc/..., read-only)
            raise InvalidInput(f"--file {str(file)!r}: cannot write the token file: {e.strerror or e}") \
                from None
        typer.echo(f"token {name!r} (scope {level}) added to {file}; it is shown only now:", err=True)
        typer.echo(token)
        return
    token, stored = new_token(name, level)
    typer.echo(f"token {name!r} (scope {level}); it is shown only now:", err=True)
    typer.echo(token)
    typer.echo("add to the hub's config:", err=True)
    typer.echo(f'[[security.client]]\nname = "{stored.name}"\nscope = "{stored.scope}"\n'
               f'id = "{stored.id}"\nhash = "{stored.hash}"', err=True)


@app.command("list")
def list_(file: Path = _FILE, config: Path = _CONFIG,
          as_json: bool = typer.Option(False, "--json", help="Print JSON for scripts.")) -> None:
    """Name, scope, id and creation time of every token (never a secret)."""
    import json

    from ._table import Column, render

    rows = [{"name": t.name, "scope": t.scope, "id": t.id, "created": t.created or "-", "where": where}
            for where, t in _tokens(file, config)]
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    if not rows:
        typer.echo("no tokens", err=True)
        return
    columns = [Column("name", "name"), Column("scope", "scope"), Column("id", "id"),
               Column("created", "created", drop=1), Column("in", "where", drop=2)]
    typer.echo("\n".join(render(columns, rows)))


@app.command(short_help="Remove a token from the token file.")
def revoke(name: str = typer.Argument(..., help="The token's name."), file: Path = _FILE,
           config: Path = _CONFIG) -> None:
    """Remove a token from the token file: a running hub refuses it within a second."""
    from wott_hub.errors import InvalidInput, NotFound
    from wott_hub.security import TokenFile

    path = file if file is not None else _config_file(config)
    if path is None:
        if config is not None and any(t.name == name for _, t in _tokens(None, config)):
            raise InvalidInput(f"token {name!r} is a [[security.client]] of {config}: delete its lines "
                               "there and restart the hub")
        raise InvalidInput("name the token file: --file FILE (or --config with [security] tokens_file)")
    try:
        TokenFile(path).revoke(name)
    except NotFound:
        if config is not None and any(t.name == name for _, t in _tokens(None, config)):
            raise InvalidInput(f"token {name!r} is a [[security.client]] of {config}: delete its lines "
                               "there and restart the hub") from None
        raise
    typer.echo(f"revoked {name!r} in {path}")


def _config_file(config: Path | None) -> Path | None:
    if config is None:
        return None
    from wott_hub.config import HubConfig

    tf = HubConfig.load(config).security.tokens_file
    return Path(tf) if tf else None


def _tokens(file: Path | None, config: Path | None) -> list[tuple[str, StoredToken]]:
    from wott_hub.errors import InvalidInput
    from wott_hub.security import TokenFile

    if file is None and config is None:
        raise InvalidInput("name the tokens: --file FILE or --config CONFIG")
    out: list[tuple[str, StoredToken]] = []
    if config is not None:
        from wott_hub.config import HubConfig

        sec = HubConfig.load(config).security
        out += [(str(config), t) for t in sec.client]
        if sec.tokens_file and file is None:
            file = Path(sec.tokens_file)
    if file is not None:
        out += [(str(file), t) for t in TokenFile(file).load()]
    return out


@tls_app.command(short_help="Write a self-signed cert.pem and key.pem.")
def selfsigned(out: Path = typer.Option(..., "--out", "-o", file_okay=False, help="Directory for the pair."),
               host: list[str] = typer.Option(["localhost", "127.0.0.1"], "--host",
                                              help="Names and addresses the certificate is valid for."),
               days: int = typer.Option(365, min=1, max=3650, help="Validity, days."),
               force: bool = typer.Option(False, "--force", help="Replace a cert.pem or key.pem already "
                                          "in --out (clients that trust the old one stop trusting the "
                                          "hub).")) -> None:
    """Write cert.pem and key.pem (a self-signed pair for a lab; clients trust cert.pem).

    An existing pair is kept unless --force: a key is not replaced by mistake.
    """
    from wott_hub.errors import Conflict, InvalidInput
    from wott_hub.security.tls import write_selfsigned

    there = [p.name for p in (out / "cert.pem", out / "key.pem") if p.exists()]
    if there and not force:
        raise Conflict(f"{out} has {' and '.join(there)} already: keep them, or replace them with --force")
    try:
        cert, key = write_selfsigned(out, host, days)
    except OSError as e:
        raise InvalidInput(f"--out {str(out)!r}: cannot write the pair: {e.strerror or e}") from None
    typer.echo(f"{cert}\n{key}")
    typer.echo(f"run the hub with --cert {cert} --key {key} (or [security] cert/key); clients trust {cert}",
               err=True)
