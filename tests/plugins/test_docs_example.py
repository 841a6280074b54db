"""The complete minimal plugin in docs/plugins.md works as written (so the example cannot rot).

The test takes the two files straight out of the doc, writes them to a temp
folder, imports the module from there (nothing installed) and registers it
with a real ``Registry``, as an entry point would; then opens a device
through the registry and reads frames from it.
"""

from __future__ import annotations

import ast
import asyncio
import importlib
import re
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from wott_hub.plugin_api import Driver, DriverError, Health, TactileFrame
from wott_hub.plugins import ENTRY_POINT_GROUP, DeviceConfig, Registry

DOC = Path(__file__).resolve().parents[2] / "docs" / "plugins.md"


def doc_block(lang: str, first_line: str) -> str:
    """The fenced ``lang`` block of docs/plugins.md whose first line is ``first_line``."""
    blocks = re.findall(rf"^```{lang}\n(.*?)^```$", DOC.read_text(), flags=re.MULTILINE | re.DOTALL)
    found = [b for b in blocks if b.splitlines()[0] == first_line]
    assert len(found) == 1, f"docs/plugins.md needs one ```{lang} block starting {first_line!r}"
    return found[0]


@pytest.fixture
def mypad(tmp_path, monkeypatch):
    """The example's module, imported from a temp folder."""
    (tmp_path / "wott_mypad.py").write_text(doc_block("python", "# wott_mypad.py"))
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("wott_mypad", None)
    yield importlib.import_module("wott_mypad")
    sys.modules.pop("wott_mypad", None)


@pytest.fixture
def registry(mypad):
    reg = Registry(entry_points=False)
    info = reg.register(mypad, "mypad", "wott-mypad", "0.1.0")
    assert info.error is None
    return reg


def test_the_example_pyproject_registers_the_module_under_the_entry_point_group():
    project = tomllib.loads(doc_block("toml", "# pyproject.toml of wott-mypad"))
    assert project["project"]["entry-points"][ENTRY_POINT_GROUP] == {"mypad": "wott_mypad"}
    assert ENTRY_POINT_GROUP == "wott-hub"
    assert "wott-hub" in project["project"]["dependencies"]
    assert project["tool"]["hatch"]["build"]["targets"]["wheel"]["only-include"] == ["wott_mypad.py"]


def test_the_example_imports_only_the_plugin_api_from_wott_hub():
    tree = ast.parse(doc_block("python", "# wott_mypad.py"))
    modules = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    modules |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert {m for m in modules if m and m.startswith("wott_hub")} == {"wott_hub.plugin_api"}


def test_the_example_provides_its_family_and_a_demo_device(registry):
    plugin = {p.name: p for p in registry.plugins()}["mypad"]
    assert plugin.error is None and plugin.families == ("mypad",)
    assert plugin.hooks == ("wott_hub_demo_devices", "wott_hub_families", "wott_hub_open_device")
    assert [(c.id, c.family) for c in registry.demo_devices()] == [("mypad-1", "mypad")]
    assert registry.families()["mypad"].schema["properties"]["rows"]["default"] == 4


def test_a_device_of_the_example_opens_and_yields_frames_of_its_mesh(registry):
    driver = registry.open_device(DeviceConfig("pad", "mypad", {"rows": 3, "cols": 5, "rate_hz": 1000}))
    assert isinstance(driver, Driver)
    assert driver.description.mesh.n_nodes == 15 and driver.description.family == "mypad"

    async def read(n: int) -> list[TactileFrame]:
        frames = []
        async for frame in driver.frames():
            frames.append(frame)
            if len(frames) == n:
                break
        await driver.close()
        return frames

    frames = asyncio.run(asyncio.wait_for(read(20), 10))
    assert all(f.displacement.shape == (15, 3) for f in frames)
    assert [f.t_ns for f in frames] == sorted(f.t_ns for f in frames)
    assert frames[0].displacement.max() == 0.0  # at rest first, then pressed in (-z) at the centre
    last = frames[-1].displacement
    assert last[:, 2].min() < 0.0 and np.argmin(last[:, 2]) == 7  # node (1, 2): the centre
    assert driver.health().state is Health.ok


def test_a_bad_setting_of_the_example_is_a_driver_error_naming_it(registry):
    with pytest.raises(DriverError, match=r"device 'big' \(family 'mypad'\): setting 'rows': .*too many"):
        registry.open_device(DeviceConfig("big", "mypad", {"rows": 100, "cols": 100}))
    with pytest.raises(DriverError, match="setting 'depth_mm'"):
        registry.open_device(DeviceConfig("neg", "mypad", {"depth_mm": -1}))
