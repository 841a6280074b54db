"""The ``gelsight-mini`` and ``digit`` families' settings (``SettingsModel``s) and how a driver is built.

One of ``source`` (a recording), ``device`` (``/dev/videoN`` or an index) or ``serial`` (the sensor's
serial number, its node found through udev) says where frames come from. A recording is probed when
the device opens (one frame read and released in the opening thread): its frame size sets the mesh and
the default scale, and a file that is no video is refused then, in one line naming ``source``.
Nothing else here imports cv2 at import time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, ClassVar

from wott_vision.settings import backoff

from wott_hub.plugin_api import (
    MATERIALS,
    BackoffSettings,
    CoordinateFrame,
    DeviceDescription,
    Meta,
    RawSignal,
    SettingsError,
    SkinShape,
    flat_pad,
    read_settings,
)

from .specs import DIGIT_LED_MAX, DIGIT_STREAMS, MINI_SIZE, default_mm_per_px

if TYPE_CHECKING:
    from wott_vision.driver import FrameReader

    from .driver import GelDriver

__all__ = ["DIGIT", "FAMILIES", "MINI", "DigitSettings", "GelSettings", "MiniSettings", "open_gel"]

MINI = "gelsight-mini"
DIGIT = "digit"
FORCE_ESTIMATE = ("the gel as an elastic (Winkler) foundation: E / h x the indented volume within twice the "
                  "contact's radius, from the calibrated depth map (E the material's modulus, h the gel's "
                  "thickness; docs/gel.md)")
NODE_PITCH_MM = 1.0
"""The node grid's spacing over the gel's view (its depth field is sampled there)."""


class GelSettings(BackoffSettings):
    """What both gel families take."""

    title: Annotated[str, Meta(description="Human-readable name; default the device id.")] | None = None
    source: Annotated[str, Meta(min_length=1, description=(
        "A recording to play: a video file, an image-sequence pattern (frames/%04d.png) or a folder of "
        "images (name order). One of source, device or serial."))] | None = None
    device: Annotated[Annotated[int, Meta(ge=0)] | Annotated[str, Meta(min_length=1)], Meta(
        extra={"expects": "a /dev/videoN path or a camera index"},
        description="The sensor's camera: /dev/videoN or an index (not tried on hardware, docs/gel.md)."
    )] | None = None
    serial: Annotated[str, Meta(min_length=1, description=(
        "The sensor's serial number (udev ID_SERIAL_SHORT): its /dev/videoN is found through udev."))
    ] | None = None
    fps: Annotated[float, Meta(gt=0, le=1000, description=(
        "Recorded frame rate of an image sequence or folder, frames/s; for a video file, given: overrides "
        "its timestamps. Default 30 for images."))] | None = None
    realtime: Annotated[bool, Meta(description=(
        "A recording plays at its frame rate like the sensor (false: as fast as processed, frames still "
        "stamped with their recorded time)."))] = True
    mm_per_px: Annotated[float, Meta(gt=0, le=10, description=(
        "Scale at the gel, mm per pixel of the processed frame; default the sensor's (docs/gel.md: Mini "
        "18.88 mm over the frame's width, Taxim's 0.0295 mm/px at 640 px; DIGIT 18.77 mm, tacto's camera)."
    ))] | None = None
    markers: Annotated[str, Meta(extra_json_schema={"enum": ["auto", "none", "grid"]}, description=(
        "Printed markers on the gel: \"auto\" (looked for, dark or bright, in a recording's first frame; a "
        "live sensor: none), \"none\", or \"grid\" (required: no rest reference without them). With markers: "
        "skinDisplacement (shear)."
    ))] = "auto"
    rest_frames: Annotated[int, Meta(ge=1, le=300, description=(
        "Frames at rest whose median is the rest reference."))] = 5
    rest_max_change: Annotated[float, Meta(gt=0, le=255, description=(
        "Largest change between two frames at rest, grey levels (99.9th percentile of the pixels)."))] = 10.0
    min_change: Annotated[float, Meta(gt=0, le=255, description=(
        "Colour change from the rest reference that counts as contact, grey levels (or 4 x the reference's "
        "own noise if larger)."))] = 8.0
    min_area_mm2: Annotated[float, Meta(gt=0, le=1000, description=(
        "Smallest contact, mm^2: smaller changed patches are noise."))] = 0.5
    radius_fraction: Annotated[float, Meta(gt=0, lt=1, description=(
        "A contact's radius is that of the area changed by more than this fraction of its peak."))] = 0.3
    calibration: Annotated[str, Meta(min_length=1, description=(
        "A depth calibration (.npz) written by `wott-hub calibrate`: depthMap, each contact's depth and a "
        "normal-force estimate; none: contacts only."))] | None = None
    thickness_mm: Annotated[float, Meta(gt=0, le=100, description="Gel thickness, mm.")] = 4.0
    material: Annotated[str, Meta(extra_json_schema={"enum": sorted(MATERIALS)}, description=(
        "Gel material (the force estimate's modulus)."))] = "ecoflex-00-30"
    record_raw_hz: Annotated[float, Meta(ge=0, le=30, description=(
        "Record the camera image in history this often, images/s; 0: never."))] = 0.0


class MiniSettings(GelSettings):
    """A GelSight Mini's settings."""

    json_schema_extra: ClassVar[dict[str, Any]] = {"title": "gelsight-mini device settings"}


class DigitSettings(GelSettings):
    """A DIGIT's settings: its stream and LED besides the common ones."""

    json_schema_extra: ClassVar[dict[str, Any]] = {"title": "digit device settings"}

    stream: Annotated[str, Meta(extra_json_schema={"enum": list(DIGIT_STREAMS)}, description=(
        "The camera stream (digit-interface's): QVGA60, QVGA30 (320x240), VGA30, VGA15 (640x480)."
    ))] = "QVGA60"
    led: Annotated[tuple[Annotated[int, Meta(ge=0, le=DIGIT_LED_MAX)], ...], Meta(
        min_length=3, max_length=3, description="LED levels (R, G, B), 0..15 each (the firmware's).")
    ] = (DIGIT_LED_MAX,) * 3


FAMILIES: dict[str, type[GelSettings]] = {MINI: MiniSettings, DIGIT: DigitSettings}


def _check(family: str, s: GelSettings) -> None:
    given = [k for k in ("source", "device", "serial") if getattr(s, k) is not None]
    if len(given) != 1:
        raise SettingsError("source: give one of source (a recording), device or serial"
                            + (f", not {' and '.join(given)}" if given else ""))
    if s.material not in MATERIALS:
        raise SettingsError(f"material: {s.material!r} is not one of {', '.join(sorted(MATERIALS))}")
    if s.markers not in ("auto", "none", "grid"):
        raise SettingsError(f"markers: {s.markers!r} is not one of auto, none, grid")
    if isinstance(s, DigitSettings) and s.stream not in DIGIT_STREAMS:
        raise SettingsError(f"stream: {s.stream!r} is not one of {', '.join(DIGIT_STREAMS)}")
    if s.source is not None and "%" not in s.source and not Path(s.source).exists():
        raise SettingsError(f"source: {s.source!r}: no such file or folder")


def _recording(s: GelSettings) -> tuple[Callable[[], FrameReader], tuple[int, int], float, Any]:
    """(open, (width, height), fps, first frame) of the recording ``s.source``, probed (see the module
    doc)."""
    from wott_vision.camera import CameraError, open_source

    from .sources import FolderReader

    src = str(s.source)
    folder = Path(src).is_dir()
    fps = s.fps or 30.0

    def open_recording() -> FrameReader:
        if folder:
            return FolderReader(src, fps, realtime=s.realtime)
        return open_source(src, fps=s.fps if (s.fps or "%" in src) else None, realtime=s.realtime)

    try:
        reader = open_recording()
    except (CameraError, OSError) as e:
        raise SettingsError(f"source: {e}") from None
    try:
        ok, frame = reader.read()
        failure = getattr(reader, "failure", "")
        rate = float(getattr(reader, "fps", fps))
    finally:
        reader.release()
    if not ok or frame is None:
        raise SettingsError(f"source: {src!r} gives no frame: {failure or 'not a video or image'}")
    h, w = frame.shape[:2]
    return open_recording, (w, h), rate, frame


def _sensor(family: str, s: GelSettings) -> tuple[Callable[[], FrameReader], tuple[int, int], float]:
    """(open, (width, height), fps) of the sensor itself (``device`` or ``serial``)."""
    from .sources import DigitCamera, MiniCamera, video_device_for_serial

    def where() -> int | str:
        if s.serial is not None:
            return video_device_for_serial(s.serial)
        device = s.device
        assert device is not None  # _check: one of the three
        return int(device) if isinstance(device, str) and device.isdigit() else device

    if isinstance(s, DigitSettings):
        w, h, fps = DIGIT_STREAMS[s.stream]
        stream, led = s.stream, (int(s.led[0]), int(s.led[1]), int(s.led[2]))
        return lambda: DigitCamera(where(), stream, led), (h, w), float(fps)  # turned 90°
    return lambda: MiniCamera(where()), MINI_SIZE, 25.0


def describe(device_id: str, family: str, s: GelSettings, size: tuple[int, int], mm_per_px: float,
             depth: bool = False, markers: bool = False) -> DeviceDescription:
    w_mm, h_mm = size[0] * mm_per_px, size[1] * mm_per_px
    cols = max(2, int(round(w_mm / NODE_PITCH_MM)) + 1)
    rows = max(2, int(round(h_mm / NODE_PITCH_MM)) + 1)
    pitch = min(w_mm / (cols - 1), h_mm / (rows - 1))
    name = "GelSight Mini" if family == MINI else "DIGIT"
    what = "contacts from colour change"
    if markers:
        what += "; shear from its markers"
    if depth:
        what += "; depth and a normal-force estimate (Winkler foundation, docs/gel.md) from its calibration"
    return DeviceDescription(
        id=device_id, title=s.title or device_id, family=family,
        shape=SkinShape("rectangularPrism", length_mm=w_mm, width_mm=h_mm, height_mm=s.thickness_mm),
        material=MATERIALS[s.material], mesh=flat_pad(rows, cols, pitch_mm=pitch, clamp_border=False,
                                                       name=family),
        epsilon_mm=0.05, thickness_mm=s.thickness_mm, frame=CoordinateFrame(origin_name="cornerOfView"),
        measures_contacts=True, force_estimate=FORCE_ESTIMATE if depth else "", shear=markers,
        description=(f"{name}: {size[0]}x{size[1]} px at {mm_per_px:.4f} mm/px ({w_mm:.1f} x {h_mm:.1f} mm); "
                     f"{what}."),
    )


def open_gel(device_id: str, family: str, settings: Mapping[str, Any], *,
             max_frames: int | None = None) -> GelDriver:
    """A ``GelDriver`` for these settings (a recording is probed; the sensor is opened when it runs)."""
    from .driver import GelDriver, GelEstimator

    s = read_settings(FAMILIES[family], settings)
    _check(family, s)
    first = None
    if s.source is not None:
        open_source, size, fps, first = _recording(s)
        name = f"recording {s.source!r}"
    else:
        open_source, size, fps = _sensor(family, s)
        name = f"{family} {s.serial or s.device!r}"
    mm_per_px = s.mm_per_px or default_mm_per_px(family, size[0])
    markers = s.markers == "grid"
    if s.markers == "auto" and first is not None:  # a recording shows whether its gel has markers
        from .markers import find_markers

        markers = find_markers(first, mm_per_px) is not None
    elif s.markers == "grid" and first is not None:
        from .markers import find_markers

        if find_markers(first, mm_per_px) is None:
            raise SettingsError(f"markers: \"grid\", but the first frame of {s.source!r} shows no marker "
                                "pattern (dark or bright dots)")
    calibration = None
    if s.calibration is not None:
        from .depth import DepthCalibration

        try:
            calibration = DepthCalibration.load(s.calibration)
        except ValueError as e:
            raise SettingsError(f"calibration: {e}") from None
        if abs(calibration.mm_per_px / mm_per_px - 1) > 0.01:
            raise SettingsError(f"calibration: made at {calibration.mm_per_px:g} mm/px, this device's frames "
                                f"are {mm_per_px:g} mm/px (calibrate at this device's frame size)")
    description = describe(device_id, family, s, size, mm_per_px, calibration is not None, markers)
    estimator = GelEstimator.of_settings(s, mm_per_px, calibration)
    estimator.markers = markers
    estimator.nodes_mm = description.mesh.nodes
    from .contacts import load_labelling

    driver = GelDriver(description, estimator, open_source, source_name=name, backoff=backoff(s),
                       max_frames=max_frames, prepare=load_labelling)
    driver.raw_signals = (RawSignal("camera", "image", (size[1], size[0]), rate_hz=fps,
                                    record_hz=float(s.record_raw_hz)),)
    if calibration is not None:
        shape = (size[1] // calibration.scale, size[0] // calibration.scale)
        driver.depth_shape = shape
        driver.raw_signals += (RawSignal("depth", "grid", shape, unit="mm", rate_hz=fps, term="depthMap"),)
    return driver
