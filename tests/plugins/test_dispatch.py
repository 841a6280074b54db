"""The registry dispatches by family: ``wott_hub_open_device`` reaches only the family's plugin.

So a plugin's hook never re-checks ``config.family`` (hookspecs.py): these
plugins do not, and each would open any device it were handed.
"""

from __future__ import annotations

import pytest

from wott_hub.plugin_api import (
    MATERIALS,
    DeviceDescription,
    Driver,
    DriverError,
    FamilyInfo,
    SkinShape,
    flat_pad,
    hookimpl,
)
from wott_hub.plugins import DeviceConfig, Registry


class StillDriver(Driver):
    async def frames(self):  # pragma: no cover - never iterated here
        return
        yield


class CountingPlugin:
    """Provides one family; counts the devices it is asked to open, whatever their family."""

    def __init__(self, family: str) -> None:
        self.family = family
        self.asked: list[str] = []

    @hookimpl
    def wott_hub_families(self):
        return [FamilyInfo(self.family, f"{self.family} test family", {"type": "object"})]

    @hookimpl
    def wott_hub_open_device(self, config):
        self.asked.append(config.id)
        return StillDriver(DeviceDescription(
            config.id, config.id, config.family, SkinShape("rectangularPrism"),
            MATERIALS["ecoflex-00-30"], flat_pad(2, 2)))


class NoOpenPlugin:
    @hookimpl
    def wott_hub_families(self):
        return [FamilyInfo("lister", "provides a family but opens nothing", {"type": "object"})]


@pytest.fixture
def plugins():
    a, b = CountingPlugin("fam-a"), CountingPlugin("fam-b")
    reg = Registry(entry_points=False, builtins=False)
    reg.register(a, "plugin-a")
    reg.register(b, "plugin-b")
    reg.register(NoOpenPlugin(), "plugin-c")
    return reg, a, b


def test_only_the_plugin_that_declared_the_family_is_asked_to_open_its_device(plugins):
    reg, a, b = plugins
    assert reg.open_device(DeviceConfig("a1", "fam-a", {})).description.family == "fam-a"
    assert reg.open_device(DeviceConfig("b1", "fam-b", {})).description.family == "fam-b"
    assert reg.open_device(DeviceConfig("a2", "fam-a", {})).description.id == "a2"
    assert (a.asked, b.asked) == (["a1", "a2"], ["b1"])


def test_a_family_whose_plugin_has_no_open_hook_asks_no_other_plugin(plugins):
    reg, a, b = plugins
    with pytest.raises(DriverError, match="'plugin-c' provides family 'lister' but does not implement"):
        reg.open_device(DeviceConfig("c1", "lister", {}))
    assert a.asked == [] and b.asked == []


def test_an_unknown_family_asks_no_plugin(plugins):
    reg, a, b = plugins
    with pytest.raises(DriverError, match="unknown family 'fam-z'"):
        reg.open_device(DeviceConfig("z1", "fam-z", {}))
    assert a.asked == [] and b.asked == []
