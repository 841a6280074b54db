"""The Foxglove layouts shipped in docs/foxglove/ are what ``robotics.layout`` makes for the demo
fleet, and name topics the mapping really writes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from wott_hub.robotics.layout import layout_for, main

DOCS = Path(__file__).resolve().parents[2] / "docs" / "foxglove"


def _demo_ids() -> list[str]:
    from wott_hub.plugins.demo import demo_devices

    return [d.id for d in demo_devices()]


@pytest.mark.parametrize("name, profile", [("wott-hub-demo.json", "foxglove"),
                                           ("wott-hub-demo-ros2.json", "ros2")])
def test_the_shipped_layouts_are_the_demo_fleets(name, profile):
    shipped = json.loads((DOCS / name).read_text())
    assert shipped == json.loads(layout_for(_demo_ids(), profile=profile)), (
        f"regenerate: uv run python -m wott_hub.robotics.layout {'--ros2 ' if profile == 'ros2' else ''}"
        f"{' '.join(_demo_ids())} | python3 -m json.tool --indent 1 > docs/foxglove/{name}")


def test_the_layout_opens_on_each_skin():
    layout = json.loads(layout_for(["barrel-1", "pad-1"]))
    tabs = layout["content"]["tabs"]
    assert [t["title"] for t in tabs] == ["barrel-1", "pad-1"]
    three = tabs[0]["content"]["items"][0]["content"]
    assert three["panelType"] == "ThreeDee" and three["config"]["followTf"] == "barrel-1"
    assert set(three["config"]["topics"]) == {"/barrel-1/scene/skin", "/barrel-1/scene/deformation",
                                              "/barrel-1/scene/contacts"}
    log = tabs[0]["content"]["items"][1]["content"]["items"][0]["content"]
    assert (log["panelType"], log["config"]["topicToRender"]) == ("Log", "/barrel-1/log")


def test_the_command_prints_a_layout_or_its_usage(capsys):
    main(["--ros2", "barrel-1"])
    ros = json.loads(capsys.readouterr().out)
    assert "/barrel_1/skin/mesh" in json.dumps(ros)
    with pytest.raises(SystemExit) as e:
        main([])
    assert e.value.code == 2 and "usage" in capsys.readouterr().err
