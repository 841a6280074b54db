"""JSON Schema pieces of the device settings the camera-based families share.

Both take a simulator (scene, frame rate, pacing) or real cameras, reconnect
with the same backoff settings and render simulated markers through
``wott_vision.render``; a family's schema splices these in among its own
properties (``BACKOFF_PROPERTIES`` is not camera-specific: it lives in
``wott_hub.plugins.settings`` and is re-exported here). Reading the settings:
``wott_vision.settings``.
"""

from __future__ import annotations

from typing import Any

from wott_hub.plugins.settings import BACKOFF_PROPERTIES

__all__ = ["BACKOFF_PROPERTIES", "RENDER_PROPERTIES", "number", "simulator_properties", "table"]


def number(default: float, description: str, **extra: Any) -> dict[str, Any]:
    return {"type": "number", "default": default, "description": description, **extra}


def table(description: str, properties: dict[str, Any]) -> dict[str, Any]:
    """A nested settings table (``[device.render]``...): closed to unknown keys, empty by default.

    ``wott_vision.settings.defaults`` fills in its properties' defaults.
    """
    return {"type": "object", "description": description, "default": {}, "additionalProperties": False,
            "properties": properties}


def simulator_properties(fps: float, **fps_limits: Any) -> dict[str, Any]:
    """``scene``, ``fps`` (default ``fps``) and ``realtime``: what a simulated source plays, and how fast."""
    return {
        "scene": {"type": "string", "default": "",
                  "description": "Scene TOML the simulator plays; empty: the bundled demo scene."},
        "fps": number(fps, "Simulator frame rate, frames/s.", exclusiveMinimum=0, **fps_limits),
        "realtime": {"type": "boolean", "default": True,
                     "description": "Simulator paces frames like a camera (false: as fast as read)."},
    }


RENDER_PROPERTIES: dict[str, Any] = {  # the simulator's image chain (wott_vision.render)
    "blur_sigma": number(1.0, "Gaussian lens blur, px.", minimum=0),
    "noise_std": number(2.0, "Sensor noise, grey levels.", minimum=0),
    "seed": {"type": "integer", "default": 0, "description": "Noise seed."},
}
