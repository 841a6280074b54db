"""How the suite is spread over xdist workers (root ``conftest.py``): the files that share loopback
mDNS run as one unit. A renamed file would silently leave the unit and run beside the others again;
a file that starts the WoT device simulator outside it would announce ``skin-7`` beside them."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def root_conftest(request):
    root = request.config.rootpath
    return root, request.config.pluginmanager.get_plugin(str(root / "conftest.py"))


def test_the_mdns_files_exist(root_conftest):
    root, conftest = root_conftest
    assert sorted(f for f in conftest.MDNS_FILES if not (root / f).is_file()) == []


def test_every_file_that_announces_the_device_simulator_is_in_the_mdns_unit(root_conftest):
    root, conftest = root_conftest
    files = [p for d in ("tests", "client") for p in Path(root, d).rglob("test_*.py") if p != Path(__file__)]
    users = {p.relative_to(root).as_posix() for p in files if "device_sim(" in p.read_text()}
    assert users and users <= conftest.MDNS_FILES


def test_the_longest_first_units_exist_once(root_conftest):
    """A renamed file would silently drop back to xdist's order (most tests first)."""
    root, conftest = root_conftest
    units = conftest.LONGEST_FIRST
    assert len(units) == len(set(units))
    assert sorted(f for f in units if f != "mdns" and not (root / f).is_file()) == []
