"""Root conftest: fixtures every test folder shares, whichever distribution it belongs to
(``until``: poll a condition inside a test's event loop).

``tests/postgres.py`` (the throw-away PostgreSQL cluster: ``pg_cluster``, ``pg_url``) is
registered here as a plugin, so ``tests/`` and ``directory/tests/`` (its own distribution)
use one cluster per session. It is loaded by path: with ``--import-mode=importlib`` the
test folders are not packages on ``sys.path``.

pytest-xdist runs the suite on a few workers (``--dist loadfile``, pyproject.toml): each file is
run whole on one worker in its order, except the files of ``MDNS_FILES``, which run one after the
other on one worker. Those announce tactile devices on loopback mDNS (the same instance names, some
of them) or assert what a browsing hub adopted: run at the same time on two workers they see each
other's devices (docs/testing.md). The grouping is a scheduler of ours, not ``xdist_group``
marks: xdist 3.8's ``loadgroup`` renames items through ``item._nodeid``, which pytest 9.2 no
longer reads, so every test became its own unit (files split across workers, the mDNS files run
at once).
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


MDNS_FILES = frozenset({
    "tests/discovery/test_mdns.py",
    "tests/discovery/test_hub_adoption.py",
    "tests/adversarial/test_adopted_devices.py",
    "client/tests/test_client.py",
})


def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with the mDNS files as one unit (the controller sees node ids only)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class FilesAndMdns(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "mdns" if path in MDNS_FILES else path

    return FilesAndMdns(config, log)


async def _until(condition, what: str, timeout_s: float = 20.0) -> None:
    """Poll ``condition`` on the running event loop every 10 ms until it holds (AssertionError naming
    ``what`` after ``timeout_s``)."""
    import asyncio

    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while not condition():
        if loop.time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.01)


@pytest.fixture(scope="session")
def until():
    """``await until(condition, what, timeout_s=20)``: the async ``eventually`` of every test folder."""
    return _until
