"""The ``flat-vision`` family's device settings: their JSON Schema and how a driver is built from them.

Nothing here imports cv2: building a driver only wires objects together; the
camera is opened (and cv2 imported) inside the driver's worker thread.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from wott_vision.schema import BACKOFF_PROPERTIES, RENDER_PROPERTIES, number, simulator_properties, table
from wott_vision.settings import backoff, check_material, defaults, section, simulator_source

from wott_hub.drivers.base import DriverError
from wott_hub.tactile import MATERIALS, CoordinateFrame, DeviceDescription, SkinShape

from .camera import PadOptics
from .depth import DepthModel
from .geometry import GRID_MAX, GRID_MIN, PadLayout
from .simulator import RenderSettings

__all__ = ["FAMILY", "SCHEMA", "demo_scene_path", "open_pad"]

FAMILY = "flat-vision"


def demo_scene_path() -> Path:
    return Path(str(resources.files("wott_driver_flatpad") / "scenes" / "demo.toml"))


OPTICS_SCHEMA = table("Pinhole camera under the gel (docs/flat-pad.md, camera model).", {
    "width": {"type": "integer", "minimum": 16, "default": 640, "description": "Image width, px."},
    "height": {"type": "integer", "minimum": 16, "default": 480, "description": "Image height, px."},
    "focal_px": number(480.0, "Focal length, px.", exclusiveMinimum=0),
    "air_gap_mm": number(20.0, "Lens to acrylic, mm.", exclusiveMinimum=0),
    "acrylic_mm": number(3.0, "Acrylic plate thickness, mm.", minimum=0),
    "acrylic_n": number(1.49, "Refractive index of the acrylic.", minimum=1),
    "gel_n": number(1.41, "Refractive index of the gel.", minimum=1),
    "principal_px": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
                     "description": "Principal point (cx, cy), px; default the image centre."},
    "centre_mm": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
                  "description": "Device (x, y) on the optical axis, mm; default the pad centre."},
})

RENDER_SCHEMA = table("Simulator image chain (source = \"sim\" only).", {
    **RENDER_PROPERTIES,
    "refine": {"type": "integer", "minimum": 1, "maximum": 8, "default": 2,
               "description": "Ground-truth marker-area grid: pitch / refine."},
})

SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "flat-vision device settings",
    "type": "object",
    "additionalProperties": False,
    "properties": {
        "title": {"type": "string", "description": "Human-readable name; default the device id."},
        "rows": {"type": "integer", "minimum": GRID_MIN, "maximum": GRID_MAX, "default": 16,
                 "description": "Marker rows (along device y)."},
        "cols": {"type": "integer", "minimum": GRID_MIN, "maximum": GRID_MAX, "default": 16,
                 "description": "Marker columns (along device x)."},
        "pitch_mm": number(1.5, "Marker spacing, mm.", exclusiveMinimum=0),
        "marker_radius_mm": number(0.35, "Printed marker radius, mm (< 0.3 pitch).", exclusiveMinimum=0),
        "thickness_mm": number(4.0, "Gel thickness, mm.", exclusiveMinimum=0),
        "material": {"type": "string", "enum": sorted(MATERIALS), "default": "ecoflex-00-50",
                     "description": "Gel material."},
        "epsilon_mm": number(0.1, "Displacement above which a node counts as deformed, mm (above the "
                             "~0.07 mm image-noise floor at rest, docs/flat-pad.md).",
                             exclusiveMinimum=0),
        "source": {"oneOf": [{"type": "integer", "minimum": 0}, {"type": "string", "minLength": 1}],
                   "default": "sim",
                   "description": "\"sim\" (simulator), a camera index, or a video file / image "
                                  "sequence pattern / stream URL."},
        **simulator_properties(60.0),
        "depth_model": {"type": "string", "default": "physical",
                        "description": "\"physical\" (ideal optics), \"calibrate\" (fit on simulated "
                                       "presses at start-up) or a JSON file written by DepthModel.save."},
        "parallax": {"type": "boolean", "default": True,
                     "description": "Correct marker areas for the foreshortening of a sloped gel seen "
                                    "off-axis (docs/flat-pad.md); false: area ratio read as depth alone."},
        **BACKOFF_PROPERTIES,
        "optics": OPTICS_SCHEMA,
        "render": RENDER_SCHEMA,
    },
}


def layout_from(s: dict[str, Any]) -> PadLayout:
    """The pad of settings ``s`` (defaults filled in)."""
    try:
        o = defaults(OPTICS_SCHEMA, s.get("optics"), "optics.")
        for key in ("principal_px", "centre_mm"):
            if key in o:
                o[key] = tuple(float(v) for v in o[key])
        optics = PadOptics(gel_mm=float(s["thickness_mm"]), **o)
        return PadLayout(int(s["rows"]), int(s["cols"]), float(s["pitch_mm"]),
                         float(s["marker_radius_mm"]), optics)
    except (TypeError, ValueError) as e:
        raise DriverError(f"flat-vision settings: {e}") from None


def describe(device_id: str, s: dict[str, Any], layout: PadLayout) -> DeviceDescription:
    span_x = (layout.cols - 1) * layout.pitch_mm
    span_y = (layout.rows - 1) * layout.pitch_mm
    return DeviceDescription(
        id=device_id, title=str(s.get("title") or device_id), family=FAMILY,
        shape=SkinShape("rectangularPrism", length_mm=span_x, width_mm=span_y,
                        height_mm=float(s["thickness_mm"])),
        material=MATERIALS[s["material"]], mesh=layout.mesh, epsilon_mm=float(s["epsilon_mm"]),
        thickness_mm=float(s["thickness_mm"]), frame=CoordinateFrame(origin_name="cornerOfPad"),
        description=f"Flat vision pad: {layout.rows}x{layout.cols} markers at {layout.pitch_mm} mm, "
                    f"one camera at {layout.optics.px_per_mm:.1f} px/mm.",
    )


def open_pad(device_id: str, settings: dict[str, Any], *, max_frames: int | None = None):
    """A ``FlatPadDriver`` for these settings (nothing is opened until it runs)."""
    from .driver import FlatPadDriver
    from .estimator import PadEstimator
    from .simulator import PadSimulator

    s = defaults(SCHEMA, settings)
    check_material(s)
    layout = layout_from(s)
    description = describe(device_id, s, layout)
    render = section(RenderSettings, RENDER_SCHEMA, s.get("render"), "render")
    spec = str(s["depth_model"])
    estimator = PadEstimator(layout, None if spec == "calibrate" else _depth_model(spec, layout),
                             parallax=bool(s["parallax"]))
    prepare = None
    if spec == "calibrate":
        def prepare() -> None:
            from .calibration import calibrate

            estimator.depth_model = calibrate(layout, render, parallax=estimator.solver.parallax)
    source = s["source"]
    if source == "sim":
        open_source, name = simulator_source(s, demo_scene_path(),
                                             lambda scene: PadSimulator(layout, scene, render))
    else:
        def open_source():
            from wott_vision.camera import open_source as open_camera

            return open_camera(source)

        name = f"camera {source!r}"
    return FlatPadDriver(description, estimator, open_source, source_name=name, backoff=backoff(s),
                         max_frames=max_frames, prepare=prepare)


def _depth_model(spec: str, layout: PadLayout) -> DepthModel:
    if spec == "physical":
        return DepthModel.physical(layout.optics)
    try:
        return DepthModel.load(spec)
    except ValueError as e:
        raise DriverError(f"depth_model: {e}") from None
