"""Optional driver capabilities are declared protocols, checked with isinstance (not getattr probing)."""

from __future__ import annotations

import ast
from pathlib import Path

from wott_hub.drivers.base import Driver, Retargetable
from wott_hub.drivers.remote import RemoteWoTDriver
from wott_hub.drivers.scene import SceneDriver

SRC = Path(__file__).resolve().parents[2] / "src" / "wott_hub"


def test_the_wot_remote_driver_declares_that_it_can_be_retargeted():
    assert issubclass(RemoteWoTDriver, Retargetable) and issubclass(RemoteWoTDriver, Driver)
    assert Retargetable in RemoteWoTDriver.__mro__  # declared, not merely shaped like one


def test_a_driver_without_the_capability_is_not_retargetable():
    assert not issubclass(SceneDriver, Retargetable)
    assert not hasattr(SceneDriver, "retarget")


def test_a_third_party_driver_with_retarget_counts_structurally():
    class Mine:
        def retarget(self, td):
            self.td = td

    assert isinstance(Mine(), Retargetable)
    assert not isinstance(object(), Retargetable)


def test_no_module_probes_a_driver_for_retarget_with_getattr():
    probes = []
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ("getattr", "hasattr") and len(node.args) >= 2
                    and isinstance(node.args[1], ast.Constant) and node.args[1].value == "retarget"):
                probes.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert probes == []
