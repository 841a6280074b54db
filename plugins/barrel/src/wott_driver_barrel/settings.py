"""The ``barrel-vision`` family's device settings: their JSON Schema and how a driver is built.

Building a driver loads the mesh, lays out the markers and loads the ONNX
model (so a model that does not fit is refused here, when the device opens,
with the reason); cameras are opened later, inside the driver's worker
thread. Nothing here imports cv2 at module level, and onnxruntime is only
imported by ``DisplacementModel`` when a device is opened.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from wott_vision.schema import BACKOFF_PROPERTIES, RENDER_PROPERTIES, number, simulator_properties, table
from wott_vision.settings import backoff, check_material, defaults, section, simulator_source

from wott_hub.drivers.base import DriverError
from wott_hub.tactile import MATERIALS, DeviceDescription, SkinShape

__all__ = ["FAMILY", "SCHEMA", "build_layout", "demo_scene_path", "open_barrel"]

FAMILY = "barrel-vision"


def demo_scene_path() -> Path:
    return Path(str(resources.files("wott_driver_barrel") / "scenes" / "demo.toml"))


_SOURCE = {"oneOf": [{"type": "integer", "minimum": 0}, {"type": "string", "minLength": 1}]}

CAMERAS_SCHEMA = table("Camera model of both fisheye cameras (docs/barrel-vision.md).", {
    "width": {"type": "integer", "minimum": 64, "default": 640, "description": "Image width, px."},
    "height": {"type": "integer", "minimum": 64, "default": 480, "description": "Image height, px."},
    "f_px": number(234.0, "Equidistant fisheye focal length (image radius per radian), px.",
                   exclusiveMinimum=0),
    "offset_mm": number(6.0, "Distance of each camera beyond its rim, along the axis, mm.", minimum=0),
})

DETECTOR_SCHEMA = table("Marker detector (wott_vision.markers; docs/vision-tracking.md).", {
    "threshold": {"type": ["integer", "null"], "minimum": 0, "maximum": 254, "default": None,
                  "description": "Grey level of a marker; null: Otsu's level per frame."},
    "min_area": number(4, "Smallest blob, px.", exclusiveMinimum=0),
    "max_area": number(2000, "Largest blob, px.", exclusiveMinimum=0),
    "split": {"type": "boolean", "default": True,
              "description": "Split blobs holding two marker cores (far markers a pixel apart)."},
    "downscale": {"enum": [1, 2], "default": 1, "description": "Detect on a half-size image."},
    "mask": {"type": "boolean", "default": True,
             "description": "Search only the annulus where markers can appear."},
})

TRACKER_SCHEMA = table("Marker tracker (wott_vision.tracking).", {
    "gate_fraction": number(0.45, "Search radius as a fraction of the marker spacing.",
                            exclusiveMinimum=0, maximum=1),
    "max_gate_px": number(25.0, "Largest search radius, px.", exclusiveMinimum=0),
    "predict": {"type": "boolean", "default": False,
                "description": "Search where the last velocity carries each marker."},
    "merge_ratio": number(1.45, "A blob this many times its marker's rest area is two markers.",
                          exclusiveMinimum=1),
})

RENDER_SCHEMA = table("Simulator image chain (source = \"sim\" only).", RENDER_PROPERTIES)

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
        **simulator_properties(30.0, maximum=240),
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
        "epsilon_mm": number(0.1, "Displacement above which a node counts as deformed, mm.",
                             exclusiveMinimum=0),
        **BACKOFF_PROPERTIES,
        "cameras": CAMERAS_SCHEMA,
        "detector": DETECTOR_SCHEMA,
        "tracker": TRACKER_SCHEMA,
        "render": RENDER_SCHEMA,
    },
}


def build_layout(cameras: dict[str, Any] | None = None):
    """The TacLink mesh, its 16 x 16 markers and the two cameras (settings ``cameras``)."""
    from wott_hub.tactile import taclink_barrel

    from .geometry import BarrelLayout, MarkerLayout, default_cameras

    c = defaults(CAMERAS_SCHEMA, cameras, "cameras.")
    try:
        cams = default_cameras(260.0, offset_mm=float(c["offset_mm"]), f_px=float(c["f_px"]),
                               width=int(c["width"]), height=int(c["height"]))
        return BarrelLayout(MarkerLayout(taclink_barrel()), cams)
    except ValueError as e:
        raise DriverError(f"cameras: {e}") from None


def describe(device_id: str, s: dict[str, Any], layout) -> DeviceDescription:
    return DeviceDescription(
        id=device_id, title=str(s.get("title") or device_id), family=FAMILY,
        shape=SkinShape("barrel", height_mm=260.0, base_radius_mm=36.28, middle_radius_mm=53.36),
        material=MATERIALS[s["material"]], mesh=layout.mesh, epsilon_mm=float(s["epsilon_mm"]),
        thickness_mm=3.0,
        description="TacLink-style barrel skin: 16 x 16 markers seen by two fisheye cameras, "
                    "marker tracking and an ONNX model to the 585 free nodes' displacement.",
    )


def open_barrel(device_id: str, settings: dict[str, Any], *, max_frames: int | None = None):
    """A ``BarrelDriver`` for these settings; raises ``DriverError`` naming the setting at fault."""
    from .driver import BarrelDriver, CameraPair
    from .estimator import BarrelEstimator
    from .model import DisplacementModel, default_model_path
    from .simulator import BarrelSimulator, RenderSettings

    s = defaults(SCHEMA, settings)
    check_material(s)
    layout = build_layout(s.get("cameras"))
    description = describe(device_id, s, layout)
    model_path = Path(s["model"]) if s["model"] else default_model_path()
    model = DisplacementModel(model_path, n_features=layout.n_features, n_cameras=len(layout.cameras),
                              free=layout.mesh.free, expect=str(s["model_input"]),
                              threads=int(s["model_threads"]))
    try:
        estimator = BarrelEstimator(layout, model, reference=str(s["reference"]),
                                    detector=defaults(DETECTOR_SCHEMA, s.get("detector"), "detector."),
                                    tracker=defaults(TRACKER_SCHEMA, s.get("tracker"), "tracker."))
    except ValueError as e:
        raise DriverError(str(e)) from None
    source = s["source"]
    if source == "sim":
        render = section(RenderSettings, RENDER_SCHEMA, s.get("render"), "render")
        open_source, name = simulator_source(s, demo_scene_path(),
                                             lambda scene: BarrelSimulator(layout, scene, render))
    else:
        if not (isinstance(source, list | tuple) and len(source) == 2):
            raise DriverError(f"source: \"sim\" or [bottom, top] camera sources, got {source!r}")
        specs = tuple(source)

        def open_source():
            return CameraPair(specs)

        name = f"cameras {list(specs)!r}"
    return BarrelDriver(description, estimator, open_source, source_name=name, backoff=backoff(s),
                        max_frames=max_frames)
