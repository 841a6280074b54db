"""Fake installed plugin distributions: real ``.dist-info`` folders with ``entry_points.txt``.

Put the folder on ``sys.path`` (or PYTHONPATH for a subprocess) and
``importlib.metadata`` finds them exactly as it finds pip-installed plugins.
"""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from wott_hub.plugins import ENTRY_POINT_GROUP

GOOD = '''
import asyncio

import numpy as np

from wott_hub.drivers.base import Driver
from wott_hub.examples import example_device
from wott_hub.plugins import DeviceConfig, FamilyInfo, hookimpl
from wott_hub.tactile import TactileFrame


class EchoDriver(Driver):
    def __init__(self, description, n):
        super().__init__(description)
        self.n = n

    async def frames(self):
        for k in range(self.n):
            await asyncio.sleep(0)
            yield TactileFrame(k + 1, np.full((self.description.mesh.n_nodes, 3), 0.0))


@hookimpl
def wott_hub_families():
    schema = {"type": "object", "additionalProperties": False,
              "properties": {"n": {"type": "integer", "minimum": 1, "default": 3},
                             "shape": {"enum": ["flat", "cylinder"], "default": "flat"}}}
    return [FamilyInfo("echo", "Test family that yields n rest frames.", schema)]


@hookimpl
def wott_hub_open_device(config):
    return EchoDriver(example_device(config.settings["shape"], config.id), config.settings["n"])


@hookimpl
def wott_hub_demo_devices():
    return [DeviceConfig("echo-1", "echo", {"n": 2})]


@hookimpl
def wott_hub_claim_td(td):
    if td.get("title", "").startswith("echo"):
        return DeviceConfig(td["title"], "echo", {})
'''

# Its hooks are called before the good plugin's (registered later: pluggy calls LIFO).
FLAKY = '''
from wott_hub.plugins import FamilyInfo, hookimpl


@hookimpl
def wott_hub_families():
    return [FamilyInfo("flaky", "Opens nothing.", {"type": "object"})]


@hookimpl
def wott_hub_open_device(config):  # no family check: the registry calls it for "flaky" only
    raise KeyError("no such camera")


@hookimpl
def wott_hub_demo_devices():
    raise ValueError("demo exploded")


@hookimpl
def wott_hub_claim_td(td):
    raise RuntimeError("claim_td exploded")
'''

BROKEN_IMPORT = '''
import os  # noqa: F401

raise RuntimeError("boom on import")
'''

MISSING_DEP = '''
import wott_no_such_dependency  # noqa: F401
'''

EXITS = '''
import sys

sys.exit(3)
'''

TYPO = '''
from wott_hub.plugins import FamilyInfo, hookimpl


@hookimpl
def wott_hub_familes():
    return [FamilyInfo("typo", "never seen", {"type": "object"})]
'''

BAD_SIGNATURE = '''
from wott_hub.plugins import hookimpl


@hookimpl
def wott_hub_families():
    return []


@hookimpl
def wott_hub_open_device(config, camera):
    return None
'''

BAD_RESULT = '''
from wott_hub.plugins import FamilyInfo, hookimpl


@hookimpl
def wott_hub_families():
    # a duplicate family, a non-FamilyInfo, an invalid schema, and one good family
    return [FamilyInfo("echo", "dup", {"type": "object"}), {"name": "dict"},
            FamilyInfo("badschema", "x", {"type": "no-such-type"}),
            FamilyInfo("fine", "ok", {"type": "object"})]


@hookimpl
def wott_hub_demo_devices():
    return "not a list"
'''

# entry-point name -> (distribution, version, module name, source)
PLUGINS = {
    "fakegood": ("wott-fake-good", "1.0.0", "wott_fake_good", GOOD),
    "fakehook": ("wott-fake-flaky", "0.2.0", "wott_fake_flaky", FLAKY),
    "fakebroken": ("wott-fake-broken", "1.2.3", "wott_fake_broken", BROKEN_IMPORT),
    "fakemissing": ("wott-fake-missing", "0.0.1", "wott_fake_missing", MISSING_DEP),
    "fakeexit": ("wott-fake-exit", "0.0.1", "wott_fake_exit", EXITS),
    "faketypo": ("wott-fake-typo", "0.0.1", "wott_fake_typo", TYPO),
    "fakesig": ("wott-fake-sig", "0.0.1", "wott_fake_sig", BAD_SIGNATURE),
    "fakeresult": ("wott-fake-result", "0.0.1", "wott_fake_result", BAD_RESULT),
}


def make_site(root: Path, names: list[str] | None = None) -> Path:
    """Write the fake plugins and their dist-info folders under ``root``; return it."""
    root.mkdir(parents=True, exist_ok=True)
    for ep_name, (dist, version, module, source) in PLUGINS.items():
        if names is not None and ep_name not in names:
            continue
        (root / f"{module}.py").write_text(textwrap.dedent(source))
        info = root / f"{dist.replace('-', '_')}-{version}.dist-info"
        info.mkdir(exist_ok=True)
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n")
        (info / "entry_points.txt").write_text(f"[{ENTRY_POINT_GROUP}]\n{ep_name} = {module}\n")
    return root


ALL_FAKES = ",".join(PLUGINS)


@pytest.fixture
def fake_site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """All fake plugins installed (on sys.path), WOTT_HUB_PLUGINS limited to them, no cached registry.

    The limit keeps the first-party plugins (and whatever their authors are
    changing today) out of these tests; they have tests of their own.
    """
    from wott_hub.plugins import reset_registry

    site = make_site(tmp_path / "site")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("WOTT_HUB_PLUGINS", ALL_FAKES)
    reset_registry()
    yield site
    reset_registry()
    for _, _, module, _ in PLUGINS.values():
        sys.modules.pop(module, None)
