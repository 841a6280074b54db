"""The ``flat-vision`` family's device settings (a ``SettingsModel``) and how a driver is built from them.

Nothing here imports cv2: building a driver only wires objects together; the
camera is opened (and cv2 imported) inside the driver's worker thread.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, ClassVar

from wott_vision.schema import FPS_DESCRIPTION, RenderTable, VisionSettings
from wott_vision.settings import backoff, check_material, recorded_rate, section, simulator_source

from wott_hub.plugin_api import (
    MATERIALS,
    CoordinateFrame,
    DeviceDescription,
    Meta,
    RawSignal,
    SettingsError,
    SettingsTable,
    SkinShape,
    model_fields,
    read_settings,
    settings_schema,
)

from .camera import PadOptics
from .depth import DepthModel
from .geometry import GRID_MAX, GRID_MIN, PadLayout
from .simulator import RenderSettings

if TYPE_CHECKING:  # the driver and camera modules import cv2: loaded when a device opens
    from wott_vision.camera import CameraReader

    from .driver import FlatPadDriver

__all__ = ["FAMILY", "SCHEMA", "SIDE_LOBE_RATIO", "OpticsTable", "PadRenderTable", "PadSettings",
           "demo_scene_path", "open_pad"]

FAMILY = "flat-vision"
SIDE_LOBE_RATIO = 0.2
"""The depth estimate's spurious one-marker peaks beside a press reach 0.18 of the press's own peak
(next to the clamped border; ``wott-hub bench accuracy``, docs/processing.md): weaker contacts beside
a stronger one are not fingers."""


def demo_scene_path() -> Path:
    return Path(str(resources.files("wott_driver_flatpad") / "scenes" / "demo.toml"))


Pair = Annotated[list[Annotated[float, Meta(ge=-100_000, le=100_000)]], Meta(min_length=2, max_length=2)]


class OpticsTable(SettingsTable, frozen=True):
    """Pinhole camera under the gel (docs/flat-pad.md, camera model)."""

    width: Annotated[int, Meta(ge=16, le=8192, description="Image width, px.")] = 640
    height: Annotated[int, Meta(ge=16, le=8192, description="Image height, px.")] = 480
    focal_px: Annotated[float, Meta(gt=0, le=100_000, description="Focal length, px.")] = 480.0
    air_gap_mm: Annotated[float, Meta(gt=0, le=1000, description="Lens to acrylic, mm.")] = 20.0
    acrylic_mm: Annotated[float, Meta(ge=0, le=100, description="Acrylic plate thickness, mm.")] = 3.0
    acrylic_n: Annotated[float, Meta(ge=1, le=3, description="Refractive index of the acrylic.")] = 1.49
    gel_n: Annotated[float, Meta(ge=1, le=3, description="Refractive index of the gel.")] = 1.41
    principal_px: Annotated[Pair, Meta(description=(
        "Principal point (cx, cy), px; default the image centre."))] | None = None
    centre_mm: Annotated[list[Annotated[float, Meta(ge=-10_000, le=10_000)]], Meta(
        min_length=2, max_length=2,
        description="Device (x, y) on the optical axis, mm; default the pad centre.")] | None = None


class PadRenderTable(RenderTable, frozen=True):
    """Simulator image chain (source = "sim" only)."""

    refine: Annotated[int, Meta(ge=1, le=8, description="Ground-truth marker-area grid: pitch / refine.")] = 2


class PadSettings(VisionSettings):
    """A flat-vision device's settings, declared once: types, bounds, defaults, descriptions;
    ``SCHEMA`` is derived for docs and the registry."""

    json_schema_extra: ClassVar[dict[str, Any]] = {"title": "flat-vision device settings"}

    rows: Annotated[int, Meta(ge=GRID_MIN, le=GRID_MAX, description="Marker rows (along device y).")] = 16
    cols: Annotated[int, Meta(ge=GRID_MIN, le=GRID_MAX, description="Marker columns (along device x).")] = 16
    pitch_mm: Annotated[float, Meta(gt=0, le=100, description="Marker spacing, mm.")] = 1.5
    marker_radius_mm: Annotated[float, Meta(gt=0, le=30, description=(
        "Printed marker radius, mm (< 0.3 pitch)."))] = 0.35
    thickness_mm: Annotated[float, Meta(gt=0, le=100, description="Gel thickness, mm.")] = 4.0
    material: Annotated[str, Meta(extra_json_schema={"enum": sorted(MATERIALS)},
                                  description="Gel material.")] = "ecoflex-00-50"
    epsilon_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Displacement above which a node counts as deformed, mm (above the ~0.07 mm image-noise "
        "floor at rest, docs/flat-pad.md)."))] = 0.1
    source: Annotated[Annotated[int, Meta(ge=0)] | Annotated[str, Meta(min_length=1)], Meta(
        extra={"expects": "\"sim\", a camera index or a video file / image sequence / stream URL"},
        description="\"sim\" (simulator), a camera index, or a video file / image sequence pattern / "
                    "stream URL.")] = "sim"
    fps: Annotated[float, Meta(gt=0, le=1000, description=FPS_DESCRIPTION)] = 60.0
    depth_model: Annotated[str, Meta(description=(
        "\"physical\" (ideal optics), \"calibrate\" (fit on simulated presses at start-up) or a JSON "
        "file written by DepthModel.save."))] = "physical"
    parallax: Annotated[bool, Meta(description=(
        "Correct marker areas for the foreshortening of a sloped gel seen off-axis (docs/flat-pad.md); "
        "false: area ratio read as depth alone."))] = True
    mm_per_px: Annotated[float, Meta(gt=0, le=10, description=(
        "Image scale at the markers at rest, mm per pixel (e.g. measured with a ruler on the pad); given, "
        "it sets optics.focal_px (focal_px = the layers' effective distance / mm_per_px)."))] | None = None
    optics: Annotated[OpticsTable, Meta(description=OpticsTable.__doc__)] = OpticsTable()
    render: Annotated[PadRenderTable, Meta(description=PadRenderTable.__doc__)] = PadRenderTable()


SCHEMA: dict[str, Any] = settings_schema(PadSettings)


def layout_from(s: PadSettings) -> PadLayout:
    """The pad of read settings ``s``."""
    try:
        o = model_fields(s.optics)
        for key in ("principal_px", "centre_mm"):
            if o[key] is not None:
                o[key] = tuple(float(v) for v in o[key])
        if s.mm_per_px is not None:  # the scale a user can measure, instead of a focal length
            z_eff = PadOptics(gel_mm=s.thickness_mm, **o).z_eff_mm
            o["focal_px"] = z_eff / s.mm_per_px
        optics = PadOptics(gel_mm=s.thickness_mm, **o)
        return PadLayout(s.rows, s.cols, s.pitch_mm, s.marker_radius_mm, optics)
    except (TypeError, ValueError) as e:
        raise SettingsError(f"flat-vision settings: {e}") from None


def describe(device_id: str, s: PadSettings, layout: PadLayout) -> DeviceDescription:
    span_x = (layout.cols - 1) * layout.pitch_mm
    span_y = (layout.rows - 1) * layout.pitch_mm
    return DeviceDescription(
        id=device_id, title=s.title or device_id, family=FAMILY,
        shape=SkinShape("rectangularPrism", length_mm=span_x, width_mm=span_y, height_mm=s.thickness_mm),
        material=MATERIALS[s.material], mesh=layout.mesh, epsilon_mm=s.epsilon_mm,
        thickness_mm=s.thickness_mm, frame=CoordinateFrame(origin_name="cornerOfPad"),
        side_lobe_ratio=SIDE_LOBE_RATIO,
        description=f"Flat vision pad: {layout.rows}x{layout.cols} markers at {layout.pitch_mm} mm, "
                    f"one camera at {layout.optics.px_per_mm:.1f} px/mm.",
    )


def open_pad(device_id: str, settings: Mapping[str, Any], *, max_frames: int | None = None) -> FlatPadDriver:
    """A ``FlatPadDriver`` for these settings (nothing is opened until it runs)."""
    from .driver import FlatPadDriver
    from .estimator import PadEstimator
    from .simulator import PadSimulator

    s = read_settings(PadSettings, settings)
    check_material(s)
    layout = layout_from(s)
    description = describe(device_id, s, layout)
    render = section(RenderSettings, s.render, "render")
    spec = s.depth_model
    estimator = PadEstimator(layout, None if spec == "calibrate" else _depth_model(spec, layout),
                             parallax=s.parallax)
    prepare = None
    if spec == "calibrate":
        def prepare() -> None:
            from .calibration import calibrate

            solver = estimator.solver
            assert solver is not None  # the estimator has depth on: there is a solver
            estimator.depth_model = calibrate(layout, render, parallax=solver.parallax)
    source = s.source
    if source == "sim":
        open_source, name = simulator_source(s, demo_scene_path(),
                                             lambda scene: PadSimulator(layout, scene, render))
    else:
        fps, realtime = recorded_rate(settings, s, source)

        def open_source() -> CameraReader:
            from wott_vision.camera import open_source as open_camera

            return open_camera(source, fps=fps, realtime=realtime)

        name = f"camera {source!r}"
    driver = FlatPadDriver(description, estimator, open_source, source_name=name, backoff=backoff(s),
                           max_frames=max_frames, prepare=prepare)
    driver.below_threshold_s = s.below_threshold_s
    optics = layout.optics
    driver.raw_signals = (RawSignal("camera", "image", (optics.height, optics.width), rate_hz=float(s.fps),
                                    record_hz=float(s.record_raw_hz)),)
    return driver


def _depth_model(spec: str, layout: PadLayout) -> DepthModel:
    if spec == "physical":
        return DepthModel.physical(layout.optics)
    try:
        return DepthModel.load(spec)
    except ValueError as e:
        raise SettingsError(f"depth_model: {e}") from None
