"""The ``barrel-vision`` family's device settings: their JSON Schema and how a driver is built.

Building a driver loads the mesh, lays out the markers and loads the ONNX
model (so a model that does not fit is refused here, when the device opens,
with the reason); cameras are opened later, inside the driver's worker
thread. Nothing here imports cv2 at module level, and onnxruntime is only
imported by ``DisplacementModel`` when a device is opened.
"""

from __future__ import annotations

from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import DriverError
from wott_hub.sim.scene import Scene, SceneError
from wott_hub.tactile import MATERIALS, DeviceDescription

__all__ = ["FAMILY", "SCHEMA", "build_layout", "demo_scene_path", "open_barrel"]

FAMILY = "barrel-vision"


def demo_scene_path() -> Path:
    return Path(str(resources.files("wott_driver_barrel") / "scenes" / "demo.toml"))


def _num(default: float, description: str, **extra: Any) -> dict[str, Any]:
    return {"type": "number", "default": default, "description": description, **extra}


_SOURCE = {"oneOf": [{"type": "integer", "minimum": 0}, {"type": "string", "minLength": 1}]}

CAMERAS_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "Camera model of both fisheye cameras (docs/barrel-vision.md).",
    "default": {},
    "additionalProperties": False,
    "properties": {
        "width": {"type": "integer", "minimum": 64, "default": 640, "description": "Image width, px."},
        "height": {"type": "integer", "minimum": 64, "default": 480, "description": "Image height, px."},
        "f_px": _num(234.0, "Equidistant fisheye focal length (image radius per radian), px.",
                     exclusiveMinimum=0),
        "offset_mm": _num(6.0, "Distance of each camera beyond its rim, along the axis, mm.", minimum=0),
    },
}

DETECTOR_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "Marker detector (wott_vision.markers; docs/vision-tracking.md).",
    "default": {},
    "additionalProperties": False,
    "properties": {
        "threshold": {"type": ["integer", "null"], "minimum": 0, "maximum": 254, "default": None,
                      "description": "Grey level of a marker; null: Otsu's level per frame."},
        "min_area": _num(4, "Smallest blob, px.", exclusiveMinimum=0),
        "max_area": _num(2000, "Largest blob, px.", exclusiveMinimum=0),
        "split": {"type": "boolean", "default": True,
                  "description": "Split blobs holding two marker cores (far markers a pixel apart)."},
        "downscale": {"enum": [1, 2], "default": 1, "description": "Detect on a half-size image."},
        "mask": {"type": "boolean", "default": True,
                 "description": "Search only the annulus where markers can appear."},
    },
}

TRACKER_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "Marker tracker (wott_vision.tracking).",
    "default": {},
    "additionalProperties": False,
    "properties": {
        "gate_fraction": _num(0.45, "Search radius as a fraction of the marker spacing.",
                              exclusiveMinimum=0, maximum=1),
        "max_gate_px": _num(25.0, "Largest search radius, px.", exclusiveMinimum=0),
        "predict": {"type": "boolean", "default": False,
                    "description": "Search where the last velocity carries each marker."},
        "merge_ratio": _num(1.45, "A blob this many times its marker's rest area is two markers.",
                            exclusiveMinimum=1),
    },
}

RENDER_SCHEMA: dict[str, Any] = {
    "type": "object",
    "description": "Simulator image chain (source = \"sim\" only).",
    "default": {},
    "additionalProperties": False,
    "properties": {
        "blur_sigma": _num(1.0, "Gaussian lens blur, px.", minimum=0),
        "noise_std": _num(2.0, "Sensor noise, grey levels.", minimum=0),
        "seed": {"type": "integer", "default": 0, "description": "Noise seed."},
    },
}

SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "barrel-vision device settings",
    "type": "object",
    "additionalProperties": False,
    "properties": {
        "title": {"type": "string", "description": "Human-readable name; default the device id."},
        "source": {"oneOf": [{"const": "sim"},
                             {"type": "array", "items": _SOURCE, "minItems": 2, "maxItems": 2}],
                   "default": "sim",
                   "description": "\"sim\" (simulator) or [bottom, top] camera sources: device index, "
                                  "video file or stream URL."},
        "scene": {"type": "string", "default": "",
                  "description": "Scene TOML the simulator plays; empty: the bundled demo scene."},
        "fps": _num(30.0, "Simulator frame rate, frames/s.", exclusiveMinimum=0, maximum=240),
        "realtime": {"type": "boolean", "default": True,
                     "description": "Simulator paces frames like cameras (false: as fast as read)."},
        "model": {"type": "string", "default": "",
                  "description": "ONNX displacement model; empty: the bundled default "
                                 "(docs/barrel-vision.md, contract)."},
        "model_input": {"enum": ["auto", "markers", "images"], "default": "auto",
                        "description": "What the model takes; auto: read it from the model's inputs."},
        "model_threads": {"type": "integer", "minimum": 1, "maximum": 8, "default": 1,
                          "description": "onnxruntime intra-op threads."},
        "reference": {"enum": ["model", "first-frame"], "default": "model",
                      "description": "Markers at rest: from the camera model, or detected in the "
                                     "first frame (skin at rest) and ordered by ray and radius."},
        "material": {"type": "string", "enum": sorted(MATERIALS), "default": "ecoflex-00-30",
                     "description": "Skin material."},
        "epsilon_mm": _num(0.1, "Displacement above which a node counts as deformed, mm.",
                           exclusiveMinimum=0),
        "backoff_initial_s": _num(0.05, "First reconnect delay, s.", exclusiveMinimum=0),
        "backoff_cap_s": _num(5.0, "Longest reconnect delay, s.", exclusiveMinimum=0),
        "cameras": CAMERAS_SCHEMA,
        "detector": DETECTOR_SCHEMA,
        "tracker": TRACKER_SCHEMA,
        "render": RENDER_SCHEMA,
    },
}


def _defaults(schema: dict[str, Any], given: dict[str, Any], where: str = "") -> dict[str, Any]:
    unknown = sorted(set(given) - set(schema["properties"]))
    if unknown:
        raise DriverError(f"unknown setting(s) {', '.join(where + u for u in unknown)}")
    out = {k: v["default"] for k, v in schema["properties"].items() if "default" in v}
    out.update(given)
    return out


def build_layout(cameras: dict[str, Any] | None = None):
    """The TacLink mesh, its 16 x 16 markers and the two cameras (settings ``cameras``)."""
    from wott_hub.tactile import taclink_barrel

    from .geometry import BarrelLayout, MarkerLayout, default_cameras

    c = _defaults(CAMERAS_SCHEMA, dict(cameras or {}), "cameras.")
    try:
        cams = default_cameras(260.0, offset_mm=float(c["offset_mm"]), f_px=float(c["f_px"]),
                               width=int(c["width"]), height=int(c["height"]))
        return BarrelLayout(MarkerLayout(taclink_barrel()), cams)
    except ValueError as e:
        raise DriverError(f"cameras: {e}") from None


def describe(device_id: str, s: dict[str, Any], layout) -> DeviceDescription:
    from wott_hub.examples import example_device

    base = example_device("barrel", device_id=device_id)
    return replace(
        base, title=str(s.get("title") or device_id), family=FAMILY, mesh=layout.mesh,
        material=MATERIALS[s["material"]], epsilon_mm=float(s["epsilon_mm"]),
        description="TacLink-style barrel skin: 16 x 16 markers seen by two fisheye cameras, "
                    "marker tracking and an ONNX model to the 585 free nodes' displacement.",
    )


def open_barrel(device_id: str, settings: dict[str, Any], *, max_frames: int | None = None):
    """A ``BarrelDriver`` for these settings; raises ``DriverError`` naming the setting at fault."""
    from .driver import BarrelDriver, CameraPair
    from .estimator import BarrelEstimator
    from .model import DisplacementModel, default_model_path
    from .simulator import BarrelSimulator, RenderSettings, SimulatedCameras

    s = _defaults(SCHEMA, settings)
    if s["material"] not in MATERIALS:
        raise DriverError(f"material: {s['material']!r} is not one of {', '.join(sorted(MATERIALS))}")
    layout = build_layout(s.get("cameras"))
    description = describe(device_id, s, layout)
    model_path = Path(s["model"]) if s["model"] else default_model_path()
    model = DisplacementModel(model_path, n_features=layout.n_features, n_cameras=len(layout.cameras),
                              free=layout.mesh.free, expect=str(s["model_input"]),
                              threads=int(s["model_threads"]))
    detector = _defaults(DETECTOR_SCHEMA, dict(s.get("detector") or {}), "detector.")
    tracker = _defaults(TRACKER_SCHEMA, dict(s.get("tracker") or {}), "tracker.")
    try:
        estimator = BarrelEstimator(layout, model, reference=str(s["reference"]), detector=detector,
                                    tracker=tracker)
        backoff = Backoff(initial_s=float(s["backoff_initial_s"]), cap_s=float(s["backoff_cap_s"]))
    except ValueError as e:
        raise DriverError(str(e)) from None
    source = s["source"]
    if source == "sim":
        try:
            scene = Scene.load(s["scene"] or demo_scene_path())
            render = RenderSettings(**_defaults(RENDER_SCHEMA, dict(s.get("render") or {}), "render."))
        except (SceneError, ValueError) as e:
            raise DriverError(f"scene/render: {e}") from None
        fps, realtime = float(s["fps"]), bool(s["realtime"])
        if not fps > 0:
            raise DriverError(f"fps: must be positive, got {fps}")

        def open_source():
            return SimulatedCameras(BarrelSimulator(layout, scene, render), fps, realtime=realtime)

        name = f"simulator ({scene.name})"
    else:
        if not (isinstance(source, list | tuple) and len(source) == 2):
            raise DriverError(f"source: \"sim\" or [bottom, top] camera sources, got {source!r}")
        specs = tuple(source)

        def open_source():
            return CameraPair(specs)

        name = f"cameras {list(specs)!r}"
    return BarrelDriver(description, estimator, open_source, source_name=name, backoff=backoff,
                        max_frames=max_frames)
