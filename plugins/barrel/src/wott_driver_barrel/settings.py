"""The ``barrel-vision`` family's device settings (a ``SettingsModel``) and how a driver is built.

Building a driver loads the mesh, lays out the markers and loads the ONNX
model (so a model that does not fit is refused here, when the device opens,
with the reason); cameras are opened later, inside the driver's worker
thread. Nothing here imports cv2 at module level, and onnxruntime is only
imported by ``DisplacementModel`` when a device is opened.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal

from wott_vision.schema import FPS_DESCRIPTION, RenderTable, VisionSettings
from wott_vision.settings import backoff, check_material, recorded_rate, section, simulator_source

from wott_hub.plugin_api import (
    MATERIALS,
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

if TYPE_CHECKING:  # the driver's modules import cv2: loaded when a device opens
    from .driver import BarrelDriver, CameraPair
    from .geometry import BarrelLayout

__all__ = ["FAMILY", "SCHEMA", "SIDE_LOBE_RATIO", "BarrelSettings", "CamerasTable", "DetectorTable",
           "TrackerTable", "build_layout", "demo_scene_path", "open_barrel"]

FAMILY = "barrel-vision"
SIDE_LOBE_RATIO = 0.2
"""The displacement model's side lobes beside a press peak at up to 0.14 of the press's own
peak (``wott-hub bench accuracy``, docs/processing.md): weaker contacts beside it are not fingers."""


def demo_scene_path() -> Path:
    return Path(str(resources.files("wott_driver_barrel") / "scenes" / "demo.toml"))


CameraSource = Annotated[int, Meta(ge=0)] | Annotated[str, Meta(min_length=1)]
"""A camera: device index, video file or stream URL."""


class CamerasTable(SettingsTable, frozen=True):
    """Camera model of both fisheye cameras (docs/barrel-vision.md)."""

    width: Annotated[int, Meta(ge=64, le=8192, description="Image width, px.")] = 640
    height: Annotated[int, Meta(ge=64, le=8192, description="Image height, px.")] = 480
    f_px: Annotated[float, Meta(gt=0, le=10_000, description=(
        "Equidistant fisheye focal length (image radius per radian), px."))] = 234.0
    offset_mm: Annotated[float, Meta(ge=0, le=1000, description=(
        "Distance of each camera beyond its rim, along the axis, mm."))] = 6.0


class DetectorTable(SettingsTable, frozen=True):
    """Marker detector (wott_vision.markers; docs/vision-tracking.md)."""

    threshold: Annotated[Annotated[int, Meta(ge=0, le=254)] | None, Meta(
        description="Grey level of a marker; null: Otsu's level per frame.")] = None
    min_area: Annotated[float, Meta(gt=0, le=1e6, description="Smallest blob, px.")] = 4
    max_area: Annotated[float, Meta(gt=0, le=1e6, description="Largest blob, px.")] = 2000
    split: Annotated[bool, Meta(description=(
        "Split blobs holding two marker cores (far markers a pixel apart)."))] = True
    downscale: Annotated[Literal[1, 2], Meta(description="Detect on a half-size image.")] = 1
    mask: Annotated[bool, Meta(description="Search only the annulus where markers can appear.")] = True


class TrackerTable(SettingsTable, frozen=True):
    """Marker tracker (wott_vision.tracking)."""

    gate_fraction: Annotated[float, Meta(gt=0, le=1, description=(
        "Search radius as a fraction of the marker spacing."))] = 0.45
    max_gate_px: Annotated[float, Meta(ge=1, le=1000, description=(
        "Largest search radius, px (at least the smallest, 1 px)."))] = 25.0
    predict: Annotated[bool, Meta(description="Search where the last velocity carries each marker.")] = False
    merge_ratio: Annotated[float, Meta(gt=1, le=10, description=(
        "A blob this many times its marker's rest area is two markers."))] = 1.45


class BarrelSettings(VisionSettings):
    """A barrel-vision device's settings, declared once: types, bounds, defaults, descriptions;
    ``SCHEMA`` is derived for docs and the registry."""

    json_schema_extra: ClassVar[dict[str, Any]] = {"title": "barrel-vision device settings"}

    source: Annotated[Literal["sim"] | Annotated[list[CameraSource], Meta(min_length=2, max_length=2)], Meta(
        extra={"expects": "\"sim\" or [bottom, top] camera sources"},
        description="\"sim\" (simulator) or [bottom, top] camera sources: device index, video file or "
                    "stream URL.")] = "sim"
    fps: Annotated[float, Meta(gt=0, le=240, description=FPS_DESCRIPTION)] = 30.0
    model: Annotated[str, Meta(description=(
        "ONNX displacement model; empty: the bundled default (docs/barrel-vision.md, contract)."))] = ""
    model_input: Annotated[Literal["auto", "markers", "images"], Meta(description=(
        "What the model takes; auto: read it from the model's inputs."))] = "auto"
    model_threads: Annotated[int, Meta(ge=1, le=8, description="onnxruntime intra-op threads.")] = 1
    reference: Annotated[Literal["model", "first-frame"], Meta(description=(
        "Markers at rest: from the camera model, or detected in the first frame (skin at rest) "
        "and ordered by ray and radius."))] = "model"
    material: Annotated[str, Meta(extra_json_schema={"enum": sorted(MATERIALS)},
                                  description="Skin material.")] = "ecoflex-00-30"
    epsilon_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Displacement above which a node counts as deformed, mm."))] = 0.1
    cameras: Annotated[CamerasTable, Meta(description=CamerasTable.__doc__)] = CamerasTable()
    detector: Annotated[DetectorTable, Meta(description=DetectorTable.__doc__)] = DetectorTable()
    tracker: Annotated[TrackerTable, Meta(description=TrackerTable.__doc__)] = TrackerTable()
    render: Annotated[RenderTable, Meta(description="Simulator image chain (source = \"sim\" only).")] = \
        RenderTable()


SCHEMA: dict[str, Any] = settings_schema(BarrelSettings)


def build_layout(cameras: Mapping[str, Any] | CamerasTable | None = None) -> BarrelLayout:
    """The TacLink mesh, its 16 x 16 markers and the two cameras (settings ``cameras``)."""
    from wott_hub.plugin_api import taclink_barrel

    from .geometry import BarrelLayout, MarkerLayout, default_cameras

    c = cameras if isinstance(cameras, CamerasTable) else \
        read_settings(BarrelSettings, {"cameras": dict(cameras or {})}).cameras
    try:
        cams = default_cameras(260.0, offset_mm=c.offset_mm, f_px=c.f_px, width=c.width, height=c.height)
        return BarrelLayout(MarkerLayout(taclink_barrel()), cams)
    except ValueError as e:
        raise SettingsError(f"cameras: {e}") from None


def describe(device_id: str, s: BarrelSettings, layout: BarrelLayout) -> DeviceDescription:
    return DeviceDescription(
        id=device_id, title=s.title or device_id, family=FAMILY,
        shape=SkinShape("barrel", height_mm=260.0, base_radius_mm=36.28, middle_radius_mm=53.36),
        material=MATERIALS[s.material], mesh=layout.mesh, epsilon_mm=s.epsilon_mm,
        thickness_mm=3.0, side_lobe_ratio=SIDE_LOBE_RATIO,
        description="TacLink-style barrel skin: 16 x 16 markers seen by two fisheye cameras, "
                    "marker tracking and an ONNX model to the 585 free nodes' displacement.",
    )


def open_barrel(device_id: str, settings: Mapping[str, Any], *,
                max_frames: int | None = None) -> BarrelDriver:
    """A ``BarrelDriver`` for these settings; raises ``SettingsError`` naming the setting at fault."""
    from .driver import BarrelDriver, CameraPair
    from .estimator import BarrelEstimator
    from .model import DisplacementModel, default_model_path
    from .simulator import BarrelSimulator, RenderSettings

    s = read_settings(BarrelSettings, settings)
    check_material(s)
    layout = build_layout(s.cameras)
    description = describe(device_id, s, layout)
    model_path = Path(s.model) if s.model else default_model_path()
    model = DisplacementModel(model_path, n_features=layout.n_features, n_cameras=len(layout.cameras),
                              free=layout.mesh.free, expect=s.model_input, threads=s.model_threads)
    try:
        estimator = BarrelEstimator(layout, model, reference=s.reference,
                                    detector=model_fields(s.detector), tracker=model_fields(s.tracker))
    except ValueError as e:
        raise SettingsError(str(e)) from None
    source = s.source
    if source == "sim":
        render = section(RenderSettings, s.render, "render")
        open_source, name = simulator_source(s, demo_scene_path(),
                                             lambda scene: BarrelSimulator(layout, scene, render))
    else:
        if not (isinstance(source, list | tuple) and len(source) == 2):
            raise SettingsError(f"source: \"sim\" or [bottom, top] camera sources, got {source!r}")
        specs = tuple(source)
        fps, realtime = recorded_rate(settings, s, specs[0])

        def open_source() -> CameraPair:
            return CameraPair(specs, fps=fps, realtime=realtime)

        name = f"cameras {list(specs)!r}"
    driver = BarrelDriver(description, estimator, open_source, source_name=name, backoff=backoff(s),
                          max_frames=max_frames)
    driver.below_threshold_s = s.below_threshold_s
    driver.raw_signals = tuple(RawSignal(cam.name, "image", (cam.height, cam.width), rate_hz=float(s.fps),
                                         record_hz=float(s.record_raw_hz)) for cam in layout.cameras)
    return driver
