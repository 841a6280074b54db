"""Root conftest: fixtures every test folder shares, whichever distribution it belongs to.

``tests/postgres.py`` (the throw-away PostgreSQL cluster: ``pg_cluster``, ``pg_url``) is
registered here as a plugin, so ``tests/`` and ``directory/tests/`` (its own distribution)
use one cluster per session. It is loaded by path: with ``--import-mode=importlib`` the
test folders are not packages on ``sys.path``.

pytest-xdist runs the suite on a few workers (``--dist loadgroup``, pyproject.toml): each file is
one group, run whole on one worker in its order, except the files marked
``xdist_group("mdns")``, which share one group. Those announce tactile devices on loopback mDNS
(the same instance names, some of them) or assert what a browsing hub adopted: run at the same
time on two workers they see each other's devices (docs/testing.md).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

_NAME = "wott_tests_postgres"


def _load_postgres_plugin():
    if _NAME in sys.modules:
        return sys.modules[_NAME]
    spec = importlib.util.spec_from_file_location(_NAME, Path(__file__).parent / "tests" / "postgres.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[_NAME] = module
    spec.loader.exec_module(module)
    return module


def pytest_configure(config) -> None:
    if not config.pluginmanager.has_plugin(_NAME):
        config.pluginmanager.register(_load_postgres_plugin(), _NAME)


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook, which reads the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.path.as_posix()))
