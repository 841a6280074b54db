"""The ``anyskin`` family for wott-hub (entry point ``anyskin`` in group ``wott-hub``).

Imports stay light here (no pyserial, no driver) until a device is opened.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

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
    read_settings,
)

__all__ = ["FAMILY", "AnySkinSettings"]

FAMILY = "anyskin"


class AnySkinSettings(BackoffSettings):
    """An AnySkin or ReSkin board's settings (docs/skins.md)."""

    # a real board needs its port; a simulated one makes its own
    json_schema_extra: ClassVar[dict[str, Any]] = {
        "if": {"not": {"required": ["simulate"], "properties": {"simulate": {"const": True}}}},
        "then": {"required": ["port"]},
    }

    port: Annotated[str, Meta(min_length=1, description=(
        "Serial device of the QT Py or Trinket (/dev/ttyACM0, COM3) or pyserial URL (socket://host:port)."
    ))] | None = None
    title: Annotated[str, Meta(description="Human-readable name; default the device id.")] | None = None
    board: Annotated[Literal["anyskin", "reskin"], Meta(description=(
        "Which 5X board: its chips' order, addresses and axes (docs/skins.md)."))] = "anyskin"
    baudrate: Annotated[int, Meta(ge=1, le=12_000_000, description=(
        "Bits per second (the firmware's 115200; USB CDC ignores it)."))] = 115200
    epsilon_ut: Annotated[float, Meta(gt=0, le=10_000, description=(
        "Change of a magnetometer's field (its norm, µT) above which it counts as touched."))] = 30.0
    baseline_samples: Annotated[int, Meta(ge=1, le=1000, description=(
        "Samples whose mean is the baseline, at start and on tare."))] = 5
    material: Annotated[str, Meta(extra_json_schema={"enum": sorted(MATERIALS)}, description=(
        "The skin's elastomer (the TD's skinMaterial only: a magnetic skin gives no force here)."))] = \
        "dragonskin-10"
    thickness_mm: Annotated[float, Meta(gt=0, le=100, description="Skin thickness over the board, mm.")] = 2.0
    simulate: Annotated[bool, Meta(description=(
        "A simulated board on a pty instead of port (a toy field model, pressed now and then)."))] = False
    rate_hz: Annotated[float, Meta(gt=0, le=2000, description="Simulated samples per second.")] = 200.0


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "AnySkin / ReSkin magnetic skin: 5 three-axis magnetometers over USB serial (binary burst stream); "
        "the field change in µT per magnetometer, contacts from it (no force).",
        AnySkinSettings,
    )]


# The boards' USB ids (docs/skins.md, "USB ids"): Adafruit's SAMD Arduino core (boards.txt,
# adafruit_qtpy_m0 0x80CB, adafruit_trinket_m0 0x801E) and CircuitPython (ports/atmel-samd/boards/
# qtpy_m0 0x80CC, trinket_m0 0x801F). AnySkin's board carries a QT Py, ReSkin's a Trinket.
_QT_PY = "Adafruit QT Py M0 (AnySkin board; {})"
_TRINKET = "Adafruit Trinket M0 (ReSkin board; {})"
USB_MATCHES = (
    UsbMatch(FAMILY, "tty", _QT_PY.format("Arduino"), vendor_id="239a", product_ids=("80cb",), setting="port",
             settings={"board": "anyskin"}),
    UsbMatch(FAMILY, "tty", _QT_PY.format("CircuitPython"), vendor_id="239a", product_ids=("80cc",),
             setting="port", settings={"board": "anyskin"}),
    UsbMatch(FAMILY, "tty", _TRINKET.format("Arduino"), vendor_id="239a", product_ids=("801e",),
             setting="port", id_prefix="reskin", settings={"board": "reskin"}),
    UsbMatch(FAMILY, "tty", _TRINKET.format("CircuitPython"), vendor_id="239a", product_ids=("801f",),
             setting="port", id_prefix="reskin", settings={"board": "reskin"}),
)


@hookimpl
def wott_hub_usb_devices() -> list[UsbMatch]:
    return list(USB_MATCHES)


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    return open_anyskin_device(config)  # the registry calls this only for FAMILY's devices


def open_anyskin_device(config: DeviceConfig) -> Driver:
    from wott_hub.plugin_api import (
        CoordinateFrame,
        DeviceDescription,
        NodeSignal,
        SettingsError,
        SkinShape,
        backoff,
    )

    from .boards import BOARDS, PITCH_MM
    from .driver import AnySkinDriver
    from .simulator import AnySkinSimulator

    with naming_device(config):
        s = read_settings(AnySkinSettings, config.settings)
        if s.port is None and not s.simulate:
            raise SettingsError("setting 'port': required setting is missing")
        if s.material not in MATERIALS:
            raise SettingsError(f"setting 'material': {s.material!r} is not one of {sorted(MATERIALS)}")
        reconnect = backoff(s)
    board = BOARDS[s.board]
    side = 20.0  # the board's sensing square, mm (20 x 29 with its connector tab)
    desc = DeviceDescription(
        id=config.id, title=s.title or config.id, family=FAMILY,
        shape=SkinShape("rectangularPrism", length_mm=side, width_mm=side, height_mm=s.thickness_mm),
        material=MATERIALS[s.material], mesh=board.mesh(),
        frame=CoordinateFrame(origin_name="centreMagnetometer"),
        epsilon_mm=s.epsilon_ut, thickness_mm=s.thickness_mm,
        description=(f"{s.board} 5X board: 5 MLX90393 magnetometers {PITCH_MM:g} mm apart in a plus; "
                     "field change in µT per magnetometer, board frame (x right, y away from the connector)"),
        node_signal=NodeSignal("magneticField"),
    )
    simulator = AnySkinSimulator(board, rate_hz=s.rate_hz) if s.simulate else None
    return AnySkinDriver(desc, board=board, port=s.port, simulator=simulator, baudrate=s.baudrate,
                         baseline_samples=s.baseline_samples, backoff=reconnect)
