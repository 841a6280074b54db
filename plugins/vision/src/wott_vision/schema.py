"""The settings the camera-based families share, declared as models (``SettingsModel``).

Both take a simulator (scene, frame rate, pacing) or real cameras, reconnect
with the same backoff settings, report a press that stays just below epsilon
and render simulated markers through ``wott_vision.render``; a family's model
inherits ``VisionSettings`` and adds its own fields (``fps`` among them: its
default and bound differ per family) and nested tables (``RenderTable`` and
its own). Every number carries its bounds; the JSON Schema the docs and
``wott-hub plugins families`` show is derived (``settings_schema``). Reading
the settings: ``wott_vision.settings``.

Models are defined at module level: msgspec resolves their annotations there.
"""

from __future__ import annotations

from typing import Annotated

from wott_hub.plugin_api import BackoffSettings, Meta, SettingsTable

__all__ = ["FPS_DESCRIPTION", "RenderTable", "VisionSettings"]


class VisionSettings(BackoffSettings):
    """Settings every camera-based family has: name, simulator, pacing, health, reconnects."""

    title: Annotated[str, Meta(description="Human-readable name; default the device id.")] | None = None
    scene: Annotated[str, Meta(description=(
        "Scene TOML the simulator plays; empty: the bundled demo scene."))] = ""
    realtime: Annotated[bool, Meta(description=(
        "Simulator and recorded files (video, image sequence) play at their frame rate like a camera "
        "(false: as fast as read, frames still stamped with their scene or recorded time)."))] = True
    below_threshold_s: Annotated[float, Meta(ge=0, le=3600, description=(
        "Report 'below threshold' in the health after a press stays between 0.75 and 1 x epsilon "
        "this long, s; 0: never."))] = 1.0
    record_raw_hz: Annotated[float, Meta(ge=0, le=30, description=(
        "Record each camera's image in history this often, images/s (PNG, ~0.8 GB per camera-hour "
        "at 1 image/s for 640 x 480: docs/tactile-td.md); 0: never, the default. Live reads and "
        "streams of the images need no recording."))] = 0.0


FPS_DESCRIPTION = ("Simulator frame rate, frames/s; for an image sequence its recorded rate; for a video "
                   "file, given: overrides the container's timestamps.")
"""The description of each family's ``fps`` field."""


class RenderTable(SettingsTable, frozen=True):
    """The simulator's image chain (``[device.render]``, source = "sim" only; wott_vision.render)."""

    blur_sigma: Annotated[float, Meta(ge=0, le=100, description="Gaussian lens blur, px.")] = 1.0
    noise_std: Annotated[float, Meta(ge=0, le=255, description="Sensor noise, grey levels.")] = 2.0
    seed: Annotated[int, Meta(description="Noise seed.")] = 0
