"""The rules across tables that ``wott-hub run`` applies when the hub is built, as a list of problems,
so that ``wott-hub config check`` says what ``run`` would refuse (issue 48 item 10).

Why a module of its own: the rules were applied only in ``Hub.__init__`` (the access policy, the
Foxglove bind) or not at all (two endpoints on one port, found as a traceback when the second bound),
so ``config check`` approved configs ``run`` refused. Both now call ``startup_problems``; ``Hub``
raises them as one ``ConfigError``. Pure: nothing is bound, read or opened here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from wott_hub.config import HubConfig

__all__ = ["startup_problems"]


def startup_problems(cfg: HubConfig) -> list[str]:
    """Every problem ``run`` would refuse ``cfg`` for, one line each (empty: it would start)."""
    from wott_hub.errors import ConfigError
    from wott_hub.robotics.config import check_bind
    from wott_hub.security.setup import REFUSAL, is_loopback

    out: list[str] = []
    where = cfg.source
    sec = cfg.security
    if (sec.cert is None) != (sec.key is None):
        out.append("[security]: cert and key go together (TLS needs both; --cert and --key)")
    if not sec.has_credentials and not is_loopback(cfg.host) and not sec.insecure:
        out.append(REFUSAL.format(host=cfg.host))  # as the hub has always said it (security/setup.py)
    try:
        check_bind(cfg.foxglove, sec.insecure)
    except ConfigError as e:
        out.append(f"{where}: [foxglove].host: {e}")
    ports = [("[hub].http_port", cfg.http_port), ("[hub].ws_port", cfg.ws_port),
             ("[hub].catalogue_port", cfg.catalogue_port), ("[foxglove].port", cfg.foxglove.port)]
    seen: dict[int, str] = {}
    for name, port in ports:
        if not port:  # None: off; 0: any free port, never the same twice
            continue
        if port in seen:
            out.append(f"{where}: {name}: {port} is also {seen[port]}: each endpoint needs a port of its own")
        else:
            seen[port] = name
    return out
