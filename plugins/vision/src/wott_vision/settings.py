"""Reading the device settings the camera-based families share (their models: ``wott_vision.schema``).

The barrel skin and the flat pad both take a simulator or real cameras, pace
reconnects the same way and nest sub-tables (``render``, ...) with their own
defaults; reading those is the same code for both. A family reads its settings
with ``read_settings(ItsModel, settings)`` (every bound checked, defaults filled
in) and hands the typed result to these helpers. ``backoff`` is not
camera-specific: it lives in ``wott_hub.plugin_api`` and is re-exported here.
Errors are ``SettingsError``s naming the setting at fault (the plugin hook adds
the device and family).
Nothing here imports cv2: the reader a family makes is opened by its driver.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from wott_hub.plugin_api import MATERIALS, Scene, SceneError, SettingsError, backoff, model_fields

from .driver import FrameReader
from .simulated import SimulatedSource, Simulator

__all__ = ["backoff", "check_material", "recorded_rate", "section", "simulator_source"]

_T = TypeVar("_T")


def recorded_rate(given: Mapping[str, Any], s: Any, source: Any) -> tuple[float | None, bool]:
    """(fps, realtime) for a camera source: an image sequence plays at ``fps`` (given or default),
    a video file at its container's timestamps unless ``fps`` is given (wott_vision.camera).
    ``given`` is the settings as written, ``s`` the family's read model."""
    sequence = isinstance(source, str) and "%" in source
    fps = float(s.fps) if sequence or "fps" in given else None
    return fps, bool(s.realtime)


def section(factory: Callable[..., _T], table: Any, key: str) -> _T:
    """``factory(**table)`` for the read sub-table ``key``; errors name ``key``."""
    try:
        return factory(**model_fields(table))
    except (TypeError, ValueError) as e:
        raise SettingsError(f"{key}: {e}") from None


def check_material(s: Any) -> None:
    if s.material not in MATERIALS:
        raise SettingsError(f"material: {s.material!r} is not one of {', '.join(sorted(MATERIALS))}")


def simulator_source(
    s: Any, demo_scene: Path, make_simulator: Callable[[Scene], Simulator],
) -> tuple[Callable[[], FrameReader], str]:
    """(``open_source``, its name) for ``source = "sim"``: ``make_simulator(scene)`` read like
    a camera at the ``fps`` setting (``SimulatedSource``) of ``s``, a family's read ``VisionSettings``.

    The scene is loaded now, so a bad one is refused when the device opens; each (re)open
    starts a fresh simulator from the scene's beginning.
    """
    try:
        scene = Scene.load(s.scene or demo_scene)
    except SceneError as e:
        raise SettingsError(f"scene: {e}") from None
    fps, realtime = float(s.fps), bool(s.realtime)
    if not fps > 0:
        raise SettingsError(f"fps: must be positive, got {fps}")

    def open_source() -> SimulatedSource:
        return SimulatedSource(make_simulator(scene), fps, realtime=realtime)

    return open_source, f"simulator ({scene.name})"
