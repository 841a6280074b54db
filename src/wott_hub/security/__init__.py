"""Who may read, control and administer the hub: tokens with scopes, one gate per server, TLS,
the audit trail (docs/security.md).

The package depends on nothing of the hub but ``errors``, ``configspec`` and (lazily,
for the audit table) ``history.models``: the servient, the network side and the CLI
use it, never the other way round.
"""

from __future__ import annotations

from .audit import AuditEntry, AuditLog, read_audit
from .config import SECURITY_TABLE, SecurityConfig, parse_security
from .policy import BEARER, BEARER_EITHER, BEARER_QUERY, AccessPolicy, Decision, Principal
from .scopes import Scope
from .setup import build_policy, is_loopback
from .tokens import StoredToken, TokenFile, TokenStore, new_token

__all__ = [
    "BEARER", "BEARER_EITHER", "BEARER_QUERY", "SECURITY_TABLE", "AccessPolicy", "AuditEntry", "AuditLog",
    "Decision", "Principal", "Scope", "SecurityConfig", "StoredToken", "TokenFile", "TokenStore",
    "build_policy", "is_loopback", "new_token", "parse_security", "read_audit",
]
