"""A Foxglove layout that opens on a fleet's skins: one tab per device, its 3D scene following its
frame, its actions' log and a plot of how many nodes are deformed.

Foxglove imports a layout file (Layouts, Import from file); a layout names topics, so it is made
for a fleet's device ids: ``python -m wott_hub.robotics.layout barrel-1 pad-1 > fleet.json``
(``--ros2`` for a rosbag2 export's topics). docs/foxglove/ holds the demo fleet's two
(tests/robotics/test_layout.py keeps them equal to what this module makes). Built with
``foxglove-sdk``'s layout classes, so the file is the format Foxglove reads.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from .mapping import FleetMapping

__all__ = ["layout_for", "main"]


def layout_for(things: Sequence[str], *, profile: str = "foxglove") -> str:
    """The layout (JSON text) for ``things``' topics in ``profile`` (``foxglove``: the MCAP export and
    the live endpoint; ``ros2``: a rosbag2 export)."""
    import foxglove.layouts as fl

    fleet = FleetMapping(profile)
    tabs = []
    for thing in things:
        enc = fleet.add(thing, None, None).enc  # the encoders name the topics (no mesh needed for that)
        scene = [enc.channel(k) for k in ("mesh", "deformation", "contacts")]
        log_ch = enc.channel("log")
        deformation = enc.channel("deformation")
        assert log_ch is not None and deformation is not None
        topics: dict[str, fl.BaseRendererTopicSettings] = {
            ch.topic: (fl.BaseRendererSceneUpdateTopicSettings(visible=True) if profile == "foxglove"
                       else fl.BaseRendererRosMarkerTopicSettings(visible=True))
            for ch in scene if ch is not None and ch.schema_name != "sensor_msgs/msg/PointCloud2"}
        if profile == "ros2":
            topics[deformation.topic] = fl.BaseRendererPointCloudTopicSettings(
                visible=True, color_field="intensity", color_mode="colormap", point_size=6)
        count = (f"{fleet.raw_channel(thing, 0, 'skinDeformedDetection').topic}.numOfDeformedNodes"
                 if profile == "foxglove" else f"{deformation.topic}.width")
        three = fl.ThreeDeePanel(title=f"{thing}: skin, deformation, contacts", config=fl.ThreeDeeConfig(
            follow_tf=thing, follow_mode="follow-pose", topics=topics,
            camera_state=fl.ThreeDeeCameraState(distance=0.25, perspective=True, phi=55, theta_offset=45)))
        side = fl.SplitContainer(direction="column", items=[
            fl.SplitItem(content=fl.LogPanel(title=f"{thing}: actions",
                                             config=fl.LogConfig(topic_to_render=log_ch.topic))),
            fl.SplitItem(content=fl.PlotPanel(title=f"{thing}: deformed nodes", config=fl.PlotConfig(
                paths=[fl.PlotSeries(value=count)]))),
        ])
        tabs.append(fl.TabItem(title=thing, content=fl.SplitContainer(direction="row", items=[
            fl.SplitItem(proportion=2, content=three), fl.SplitItem(proportion=1, content=side)])))
    return fl.Layout(content=fl.TabContainer(tabs=tabs)).to_json()


def main(argv: Sequence[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    profile = "ros2" if "--ros2" in args else "foxglove"
    things = [a for a in args if a != "--ros2"]
    if not things:
        print("usage: python -m wott_hub.robotics.layout [--ros2] DEVICE [DEVICE...]", file=sys.stderr)
        raise SystemExit(2)
    print(layout_for(things, profile=profile))


if __name__ == "__main__":
    main()
