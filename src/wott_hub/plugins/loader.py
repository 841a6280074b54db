"""Find and import driver plugins, one at a time, so one broken plugin breaks only itself.

pluggy's own ``load_setuptools_entrypoints`` stops at the first plugin that
fails to import; a gateway must not lose every device because a third-party
driver has a missing dependency. So we iterate the entry points ourselves,
import each inside its own try, and keep the failure (with the distribution's
name and version) to show in ``wott-hub plugins list``.

``WOTT_HUB_PLUGINS`` (comma-separated entry-point or distribution names)
limits which plugins are imported at all; unset means all, empty means none
(the built-in ``scene`` family is always there).
"""

from __future__ import annotations

import importlib
import os
import re
import traceback
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

__all__ = ["ENTRY_POINT_GROUP", "ENV_VAR", "Candidate", "describe_exception", "discover", "selected_names"]

# Named after the project, not a module (like datasette's "datasette"): the group is a
# registration key that outlives any reorganisation of the packages.
ENTRY_POINT_GROUP = "wott-hub"
ENV_VAR = "WOTT_HUB_PLUGINS"
_IMPORTLIB_DIR = os.path.dirname(importlib.__file__)


@dataclass(frozen=True)
class Candidate:
    """One entry point after the import attempt: a module, or the error that stopped it."""

    name: str
    distribution: str | None
    version: str | None
    module: Any = None
    error: str | None = None


def normalise(name: str) -> str:
    """PEP 503 normalisation, so ``wott_driver_taxel`` selects ``wott-driver-taxel``."""
    return re.sub(r"[-_.]+", "-", name.strip()).lower()


def selected_names(environ: Mapping[str, str] | None = None) -> set[str] | None:
    """The names ``WOTT_HUB_PLUGINS`` selects, normalised; None when the variable is unset."""
    raw = (os.environ if environ is None else environ).get(ENV_VAR)
    if raw is None:
        return None
    return {normalise(n) for n in raw.split(",") if n.strip()}


def describe_exception(exc: BaseException) -> str:
    """``Type: message (file:line)`` with the innermost frame: enough to find the fault."""
    text = f"{type(exc).__name__}: {exc}".rstrip(": ")
    # Import machinery frames (<frozen importlib._bootstrap>, importlib/) say nothing about the plugin.
    frames = [f for f in traceback.extract_tb(exc.__traceback__)
              if not f.filename.startswith(("<", _IMPORTLIB_DIR)) and f.filename != __file__]
    if frames:
        last = frames[-1]
        text += f" ({os.path.basename(last.filename)}:{last.lineno})"
    return text


def _dist_of(ep: EntryPoint) -> tuple[str | None, str | None]:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return None, None
    try:
        return dist.metadata["Name"], dist.version
    except Exception:  # a dist-info with broken METADATA must not break loading
        return None, None


def discover(
    group: str = ENTRY_POINT_GROUP, only: Iterable[str] | None = None
) -> Iterator[Candidate]:
    """Import every plugin of ``group`` (those in ``only`` if given), yielding each outcome.

    Names in ``only`` that match no installed plugin are yielded as candidates
    with an error, so a typo in ``WOTT_HUB_PLUGINS`` is visible, not silent.
    """
    wanted = None if only is None else {normalise(n) for n in only}
    matched: set[str] = set()
    for ep in sorted(entry_points(group=group), key=lambda e: e.name):
        dist_name, version = _dist_of(ep)
        keys = {normalise(ep.name)} | ({normalise(dist_name)} if dist_name else set())
        if wanted is not None:
            if not keys & wanted:
                continue
            matched |= keys & wanted
        try:
            module = ep.load()
        except (Exception, SystemExit) as e:  # a plugin calling sys.exit() on import is broken too
            yield Candidate(ep.name, dist_name, version, error=describe_exception(e))
            continue
        yield Candidate(ep.name, dist_name, version, module=module)
    for name in sorted((wanted or set()) - matched):
        yield Candidate(name, None, None,
                        error=f"named in {ENV_VAR} but no installed plugin is called {name!r}")
