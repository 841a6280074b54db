"""The ``[security]`` table of the hub config (docs/security.md, docs/configuration.md).

Declared like ``[directory]`` (``wott_hub.network.config``): each key once, with its
bounds and its words for errors, read by ``wott_hub.configspec``. A client entry holds
a token's hash, never the token: ``wott-hub tokens create NAME --scope S`` prints
both the token (once) and the ``[[security.client]]`` lines to paste.

Relative paths (token file, certificate, key) are resolved against the config file's
directory by ``HubConfig.load``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any

from wott_hub.configspec import ConfigError, Flag, Model, doc, read, says, table_of

from .tokens import StoredToken

__all__ = ["SECURITY_TABLE", "SecurityConfig", "parse_security"]

Text = Annotated[str, says("a non-empty string", pattern=r"\S")]
Origin = Annotated[str, says("an origin like https://host:port", pattern=r"^https?://[^/?#\s]+$")]
Origins = Annotated[tuple[Origin, ...], says("a list of origins")]
ScopeText = Annotated[str, says("read, control or admin", pattern=r"^(read|control|admin)$")]
Hash = Annotated[str, says("a token hash (scrypt$...)",
                          pattern=r"^scrypt\$\d+\$\d+\$\d+\$[A-Za-z0-9_-]+\$[A-Za-z0-9_-]+$")]
TokenId = Annotated[str, says("8 hex digits", pattern=r"^[0-9a-f]{8}$")]


class ClientTable(Model):
    """``[[security.client]]``: name, scope, id and hash as ``wott-hub tokens create`` prints them."""

    name: Text
    scope: ScopeText
    id: TokenId
    hash: Hash


@dataclass(frozen=True)
class SecurityConfig:
    tokens_file: Text | None = field(default=None, metadata=doc(
        "JSON file of hashed tokens (wott-hub tokens create NAME --scope S --file F); re-read when it "
        "changes, so a revoked token stops working without a restart."))
    client: tuple[StoredToken, ...] = field(default=(), metadata=doc(
        "[[security.client]] entries: { name, scope, id, hash } as wott-hub tokens create prints them."))
    cert: Text | None = field(default=None, metadata=doc(
        "PEM certificate (chain): HTTP and WebSocket are served over TLS (https, wss)."))
    key: Text | None = field(default=None, metadata=doc("PEM private key of cert."))
    cors_origins: Origins = field(default=(), metadata=doc(
        "Origins whose pages may read the hub cross-origin when it is not on loopback "
        "(on loopback: any)."))
    insecure: Flag = field(default=False, metadata=doc(
        "Serve everything without credentials on a non-loopback address (wott-hub run --insecure)."))

    @property
    def has_credentials(self) -> bool:
        return bool(self.client) or self.tokens_file is not None

    @property
    def tls(self) -> bool:
        return self.cert is not None

    def resolved(self, base: Path) -> SecurityConfig:
        """Paths relative to ``base`` (the config file's directory) made absolute."""
        def fix(p: str | None) -> str | None:
            return None if p is None or Path(p).is_absolute() else str((base / p).resolve())

        return replace(self, tokens_file=fix(self.tokens_file) or self.tokens_file,
                       cert=fix(self.cert) or self.cert, key=fix(self.key) or self.key)


SECURITY_TABLE = table_of(SecurityConfig, "security", types={
    "client": Annotated[tuple[ClientTable, ...], says("a list of tables { name, scope, id, hash }")]})
"""The ``[security]`` table as it is written in a file."""


def parse_security(table: Any, source: str) -> SecurityConfig:
    where = f"{source}: [security]"
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: must be a table")
    t = read(SECURITY_TABLE, table, where)
    if (t.cert is None) != (t.key is None):
        raise ConfigError(f"{where}: cert and key go together (TLS needs both)")
    names: set[str] = set()
    clients = []
    for i, c in enumerate(t.client):
        if c.name in names:
            raise ConfigError(f"{where}.client[{i}].name: {c.name!r} is used by another client")
        names.add(c.name)
        clients.append(StoredToken(c.id, c.name, c.scope, c.hash))
    return SecurityConfig(tokens_file=t.tokens_file, client=tuple(clients), cert=t.cert, key=t.key,
                          cors_origins=t.cors_origins, insecure=t.insecure)


