"""Reading the device settings the camera-based families share (their schema: ``wott_vision.schema``).

The barrel skin and the flat pad both take a simulator or real cameras, pace
reconnects the same way and nest sub-tables (``render``, ...) with their own
defaults; reading those is the same code for both. ``defaults`` and ``backoff``
are not camera-specific: they live in ``wott_hub.plugins.settings`` and are
re-exported here. Errors are ``DriverError``s naming the setting at fault (the
plugin hook adds the device and family).
Nothing here imports cv2: the reader a family makes is opened by its driver.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from wott_hub.drivers.base import DriverError
from wott_hub.plugins.settings import backoff, defaults
from wott_hub.sim.scene import Scene, SceneError
from wott_hub.tactile import MATERIALS

from .driver import FrameReader
from .simulated import SimulatedSource, Simulator

__all__ = ["backoff", "check_material", "defaults", "section", "simulator_source"]


def section(factory: Callable[..., Any], schema: dict[str, Any], given: dict[str, Any] | None, key: str):
    """``factory(**table)`` for the sub-table ``key`` with its defaults; errors name ``key``."""
    table = defaults(schema, given, f"{key}.")
    try:
        return factory(**table)
    except (TypeError, ValueError) as e:
        raise DriverError(f"{key}: {e}") from None


def check_material(s: dict[str, Any]) -> None:
    if s["material"] not in MATERIALS:
        raise DriverError(f"material: {s['material']!r} is not one of {', '.join(sorted(MATERIALS))}")


def simulator_source(
    s: dict[str, Any], demo_scene: Path, make_simulator: Callable[[Scene], Simulator],
) -> tuple[Callable[[], FrameReader], str]:
    """(``open_source``, its name) for ``source = "sim"``: ``make_simulator(scene)`` read like
    a camera at the ``fps`` setting (``SimulatedSource``).

    The scene is loaded now, so a bad one is refused when the device opens; each (re)open
    starts a fresh simulator from the scene's beginning.
    """
    try:
        scene = Scene.load(s["scene"] or demo_scene)
    except SceneError as e:
        raise DriverError(f"scene: {e}") from None
    fps, realtime = float(s["fps"]), bool(s["realtime"])
    if not fps > 0:
        raise DriverError(f"fps: must be positive, got {fps}")

    def open_source() -> SimulatedSource:
        return SimulatedSource(make_simulator(scene), fps, realtime=realtime)

    return open_source, f"simulator ({scene.name})"
