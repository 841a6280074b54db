"""From the ``[security]`` table and the listening address to an ``AccessPolicy``, or a refusal.

The safe defaults (docs/security.md): on a loopback address with no credentials
configured everything stays open, as the demo always was; on any other address
without credentials the hub refuses to start (``ConfigError``: one line, exit code 2,
saying how to create a token) unless ``insecure`` is set (``wott-hub run --insecure``).
With credentials, every route but the public ones needs a token, on any address.
"""

from __future__ import annotations

import ipaddress

from wott_hub.errors import ConfigError

from .config import SecurityConfig
from .policy import AccessPolicy
from .tokens import TokenStore

__all__ = ["REFUSAL", "build_policy", "is_loopback"]

REFUSAL = ("refusing to listen on {host} without credentials: create a token with "
           "'wott-hub tokens create NAME --scope read --file tokens.json' and set [security] tokens_file "
           "(or run with --tokens tokens.json), or pass --insecure to serve everyone")


def is_loopback(host: str) -> bool:
    if host in ("localhost", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def build_policy(cfg: SecurityConfig, host: str) -> AccessPolicy:
    if (cfg.cert is None) != (cfg.key is None):
        raise ConfigError("[security]: cert and key go together (TLS needs both; --cert and --key)")
    loopback = is_loopback(host)
    if not cfg.has_credentials and not loopback and not cfg.insecure:
        raise ConfigError(REFUSAL.format(host=host))
    store = TokenStore(cfg.client, cfg.tokens_file) if cfg.has_credentials else None
    return AccessPolicy(store=store, enforced=store is not None and not cfg.insecure, tls=cfg.tls,
                        cors_origins=cfg.cors_origins, restrict_cors=not loopback)
