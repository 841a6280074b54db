"""The ``taxel-array`` family for wott-hub (entry point ``taxel`` in group ``wott-hub``).

Imports stay light here (no pyserial until a device is opened) so that listing
plugins or loading the registry costs nothing for hubs without taxel arrays.
"""

from __future__ import annotations

from importlib import resources
from typing import Annotated, Any, ClassVar, Literal, NamedTuple

from wott_hub.plugin_api import (
    MATERIALS,
    BackoffSettings,
    DeviceConfig,
    Driver,
    FamilyInfo,
    Meta,
    UsbMatch,
    hookimpl,
    naming_device,
    settings_schema,
)

FAMILY = "taxel-array"
DEMO_SCENE = "demo.toml"


class Preset(NamedTuple):
    """A protocol's defaults: its array, its line speed, and ε in counts for an uncalibrated matrix."""

    rows: int
    cols: int
    baudrate: int
    epsilon_counts: float | None  # None: a calibrated array (pressure, ε in mm)


PRESETS = {
    "binary": Preset(16, 16, 921600, None),
    "ascii": Preset(16, 16, 921600, None),
    # flexitac 0.3.1 (PyPI): 12 x 32 at 2,000,000 baud, contact threshold 25 counts above the baseline
    "flexitac": Preset(12, 32, 2_000_000, 25.0),
    # 3D-ViTac MatrixArray.ino: 16 x 16 at 2,000,000 baud; multi_thread_contact.py: THRESHOLD = 12
    "3dvitac": Preset(16, 16, 2_000_000, 12.0),
}
SIM_MM_PER_COUNT = 0.01
"""A simulated 8-bit matrix reads one count per 10 µm of inward displacement (about 2 mm to full scale)."""

class TaxelSettings(BackoffSettings):
    """A taxel array's settings, declared once: types, bounds (NaN and infinities can pass none
    of them), defaults and descriptions; ``SCHEMA`` is derived for docs and the registry."""

    json_schema_extra: ClassVar[dict[str, Any]] = {
        # A real board needs its port; a simulated one makes its own.
        "if": {"not": {"required": ["simulate"], "properties": {"simulate": {"const": True}}}},
        "then": {"required": ["port"]},
    }

    title: Annotated[str, Meta(description="Human-readable name; default the device id.")] | None = None
    port: Annotated[str, Meta(min_length=1, description=(
        "Serial device (/dev/ttyUSB0, COM3) or pyserial URL (socket://host:port)."))] | None = None
    baudrate: Annotated[int, Meta(ge=1, le=12_000_000, description=(
        "Bits per second; default the protocol's (921600; flexitac and 3dvitac 2000000)."))] | None = None
    protocol: Annotated[Literal["binary", "ascii", "flexitac", "3dvitac"], Meta(
        description=("Framed binary or ASCII lines (docs/taxel-protocol.md), or an uncalibrated matrix: "
                     "FlexiTac, 3D-ViTac (docs/skins.md)."))] = "binary"
    rows: Annotated[int, Meta(ge=2, le=255, description=(
        "Taxel rows (along device y); default the protocol's (16; flexitac 12)."))] | None = None
    cols: Annotated[int, Meta(ge=2, le=255, description=(
        "Taxel columns (along device x); default the protocol's (16; flexitac 32)."))] | None = None
    pitch_mm: Annotated[float, Meta(gt=0, le=100, description="Taxel spacing, mm.")] = 4.0
    material: Annotated[str, Meta(extra_json_schema={"enum": sorted(MATERIALS)}, description=(
        "Skin over the taxels (its modulus sets the compliance)."))] = "ecoflex-00-30"
    thickness_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Skin thickness over the taxels, mm."))] = 3.0
    kpa_per_count: Annotated[float, Meta(gt=0, le=10, description=(
        "Pressure of one count of a 16-bit taxel value, kPa."))] = 0.01
    epsilon_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Displacement above which a taxel counts as deformed, mm (binary, ascii)."))] = 0.05
    epsilon_counts: Annotated[float, Meta(gt=0, le=255, description=(
        "Counts above the baseline from which a taxel counts as pressed (flexitac, 3dvitac); default "
        "the makers' readers' thresholds (flexitac 25, 3dvitac 12)."))] | None = None
    baseline_frames: Annotated[int, Meta(ge=1, le=1000, description=(
        "Frames whose per-taxel median is the baseline (flexitac, 3dvitac), at start and on tare."))] = 30
    simulate: Annotated[bool, Meta(description=(
        "Play a scene on a simulated board over a pty instead of opening port."))] = False
    scene: Annotated[str, Meta(description=(
        "Scene TOML the simulator plays; default the bundled demo scene."))] | None = None
    rate_hz: Annotated[float, Meta(gt=0, le=2000, description="Simulator frame rate, frames/s.")] = 100.0
    record_raw_hz: Annotated[float, Meta(ge=0, le=200, description=(
        "Record the pressure grid in history this often, grids/s (pressureGridRecorded events, ~2 KB "
        "each for 16 x 16: what learning exports read); 0: never, the default."))] = 0.0


SCHEMA: dict[str, Any] = settings_schema(TaxelSettings)


# Boards of the uncalibrated matrices (docs/skins.md, "USB ids"): FlexiTac's firmware is flashed to
# an Arduino Uno (its README: --fqbn arduino:avr:uno), whose ids are Arduino's AVR core's
# (boards.txt: uno.vid/pid 2341:0043, 2341:0001, 2a03:0043, 2341:0243, 2341:006a); 3D-ViTac's readme
# binds its board by an FTDI serial number ("FT6S4DSP"): an FT232R, 0403:6001 (Linux
# drivers/usb/serial/ftdi_sio_ids.h), as on an Arduino Nano. An Uno or an FTDI cable may well be
# something else: adopted only where [usb] adopt names this family.
USB_MATCHES = (
    *(UsbMatch(FAMILY, "tty", "Arduino Uno (FlexiTac readout)", vendor_id=v, product_ids=p, setting="port",
               id_prefix="flexitac", settings={"protocol": "flexitac"})
      for v, p in (("2341", ("0043", "0001", "0243", "006a")), ("2a03", ("0043",)))),
    UsbMatch(FAMILY, "tty", "FTDI FT232R USB-serial (3D-ViTac readout, e.g. an Arduino Nano)",
             vendor_id="0403", product_ids=("6001",), setting="port", id_prefix="3dvitac",
             settings={"protocol": "3dvitac"}),
)


@hookimpl
def wott_hub_usb_devices() -> list[UsbMatch]:
    return list(USB_MATCHES)


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "Serial taxel array: rows x cols pressure cells over pyserial (framed binary or ASCII lines); "
        "pressure -> normal displacement through the skin's compliance.",
        TaxelSettings,
    )]


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    return open_taxel_device(config)  # the registry calls this only for FAMILY's devices


@hookimpl
def wott_hub_demo_devices() -> list[DeviceConfig]:
    return [DeviceConfig("taxel-1", FAMILY, {"title": "Taxel array (simulated)", "simulate": True})]


def demo_scene_text() -> str:
    return resources.files("wott_driver_taxel").joinpath("scenes", DEMO_SCENE).read_text()


def open_taxel_device(config: DeviceConfig) -> Driver:
    """Build the driver from validated settings (defaults filled in by the registry)."""
    import tomllib
    from dataclasses import replace

    from wott_hub.plugin_api import (
        CoordinateFrame,
        DeviceDescription,
        NodeSignal,
        Scene,
        SceneError,
        SettingsError,
        SkinShape,
        backoff,
        flat_pad,
        read_settings,
    )

    from .compliance import Compliance
    from .driver import TaxelDriver
    from .protocol import MAX_VALUES
    from .simulator import TaxelSimulator

    with naming_device(config):
        s = read_settings(TaxelSettings, config.settings)
        preset = PRESETS[s.protocol]
        rows, cols = s.rows or preset.rows, s.cols or preset.cols
        counted = preset.epsilon_counts is not None  # an uncalibrated matrix: its counts, not pressure
        if s.port is None and not s.simulate:
            raise SettingsError("setting 'port': required setting is missing")
        if s.material not in MATERIALS:
            raise SettingsError(f"setting 'material': {s.material!r} is not one of {sorted(MATERIALS)}")
        if not counted and rows * cols > MAX_VALUES:
            raise SettingsError(f"setting 'rows': {rows} x {cols} taxels do not fit a frame "
                                f"(max {MAX_VALUES} values)")
        if s.backoff_cap_s < s.backoff_initial_s:
            raise SettingsError("setting 'backoff_cap_s': must not be below backoff_initial_s")
        reconnect = backoff(s)
    pitch, thickness = s.pitch_mm, s.thickness_mm
    material = MATERIALS[s.material]
    mesh = flat_pad(rows, cols, pitch_mm=pitch, clamp_border=False, name=f"taxel-{rows}x{cols}")
    epsilon = s.epsilon_mm if preset.epsilon_counts is None else s.epsilon_counts or preset.epsilon_counts
    desc = DeviceDescription(
        id=config.id, title=s.title or config.id, family=FAMILY,
        shape=SkinShape("rectangularPrism", length_mm=cols * pitch, width_mm=rows * pitch,
                        height_mm=thickness),
        material=material, mesh=mesh, frame=CoordinateFrame(origin_name="cornerOfPad"),
        epsilon_mm=epsilon, thickness_mm=thickness,
        description=f"{rows} x {cols} taxel array, {pitch:g} mm pitch, {s.protocol} protocol"
                    + (" (counts above a baseline, no pressure calibration)" if counted else ""),
        node_signal=NodeSignal("taxelSignal") if counted else NodeSignal(),
    )
    modulus_kpa = material.modulus_mpa * 1000.0
    compliance = Compliance(modulus_kpa, thickness, s.kpa_per_count)
    simulator = None
    if s.simulate:
        with naming_device(config):
            try:
                if s.scene is not None:
                    scene = Scene.load(s.scene)
                else:
                    scene = Scene.from_dict(tomllib.loads(demo_scene_text()),
                                            source=f"wott_driver_taxel/scenes/{DEMO_SCENE}")
            except SceneError as e:
                raise SettingsError(f"setting 'scene': {e}") from None
        wire = compliance  # an 8-bit matrix reads a coarser count
        if counted:
            wire = Compliance(modulus_kpa, thickness, SIM_MM_PER_COUNT * modulus_kpa / thickness)
        simulator = TaxelSimulator(scene, mesh, (rows, cols), wire, rate_hz=s.rate_hz, protocol=s.protocol)
        desc = replace(desc, description=desc.description + " (simulated)")
    return TaxelDriver(
        desc, shape=(rows, cols), compliance=None if counted else compliance,
        baseline_frames=s.baseline_frames, port=s.port, baudrate=s.baudrate or preset.baudrate,
        protocol=s.protocol, simulator=simulator, backoff=reconnect, record_hz=s.record_raw_hz,
    )
