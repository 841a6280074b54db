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
    if not hasattr(config, "workerinput"):  # once, in the process that starts the workers
        _compile_workspace()


def _compile_workspace() -> None:
    """Write the ``.pyc`` of the workspace's own sources (the hub, the directory, the plugins, the
    client, configspec) before any test starts a Python process.

    ``uv sync --compile-bytecode`` compiles what is installed in the venv, not the workspace members
    installed editable from their ``src`` folders; where ``PYTHONDONTWRITEBYTECODE`` is set (CI, this
    machine) their ~170 modules were compiled from source again by every process the suite starts:
    ~0.6 s of CPU for each ``wott-hub run`` (a start-up and stop cost ~3.8 s of CPU, ~3.0 s with
    them), each ``wott-hub`` command, each hub's history process. Up to date files are only
    stat'ed (~30 ms in all); a file edited later is compiled again (its ``.pyc`` records the
    source's size and time)."""
    import compileall

    root = Path(__file__).resolve().parent
    for src in sorted({root / "src", *root.glob("*/src"), *root.glob("plugins/*/src")}):
        compileall.compile_dir(src, quiet=2)


MDNS_FILES = frozenset({
    "tests/discovery/test_mdns.py",
    "tests/discovery/test_hub_adoption.py",
    "tests/adversarial/test_adopted_devices.py",
    "client/tests/test_client.py",
})


LONGEST_FIRST = (
    "tests/interop/test_td_validators.py",
    "tests/adversarial/test_spool_files.py",
    "tests/adversarial/test_foxglove_viewers.py",
    "tests/hub/test_processes.py",
    "tests/adversarial/test_rosbag2_export.py",
    "tests/adversarial/test_directory_budget.py",
    "tests/adversarial/test_token_items.py",
    "tests/scale/test_fleet.py",
    "mdns",
    "plugins/barrel/tests/test_model_accuracy.py",
    "tests/adversarial/test_export_flood.py",
    "tests/discovery/test_usb_hotplug.py",
    "tests/adversarial/test_mqtt_state.py",
    "tests/adversarial/test_retention_bytes.py",
    "tests/cli/test_demo.py",
    "tests/history/learning/test_bounded_memory.py",
    "tests/adversarial/test_held_queue_bytes.py",
    "tests/adversarial/test_audit_bounds.py",
    "tests/security/test_nodewot_bearer.py",
    "tests/adversarial/test_slow_subscribers.py",
    "tests/history/learning/test_episodes_and_bad_input.py",
    "tests/web/test_twin_device.py",
    "tests/cli/test_calibrate.py",
    "plugins/gel/tests/test_hub.py",
    "tests/web/test_twin_geometry.py",
    "tests/adversarial/test_config_items.py",
    "tests/interop/test_nodewot_credentials.py",
)
"""The units (files, ``mdns``) that took longest in a full run (``--durations=0``, summed by file),
longest first: the scheduler hands them out before the rest, so that the last unit a worker takes is
a short one and the workers finish together (a long file taken last keeps one worker busy while the
others are idle). Only an order: a file missing here, or a list gone stale, still runs whole."""


def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with the mDNS files as one unit (the controller sees node ids only), the
    ``LONGEST_FIRST`` units handed out first (then xdist's order: most tests first)."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class FilesAndMdns(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "mdns" if path in MDNS_FILES else path

        def _assign_work_unit(self, node) -> None:
            if not getattr(self, "_longest_first", False):  # the queue is whole at the first assignment
                self._longest_first = True
                for scope in reversed(LONGEST_FIRST):
                    if scope in self.workqueue:
                        self.workqueue.move_to_end(scope, last=False)
            super()._assign_work_unit(node)

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
