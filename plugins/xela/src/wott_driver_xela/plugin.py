"""The ``xela`` family for wott-hub (entry point ``xela`` in group ``wott-hub``): one Thing per sensor
position of a running ``xela_server``. Imports stay light (no tornado client) until a device opens."""

from __future__ import annotations

from typing import Annotated, Literal

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

__all__ = ["FAMILY", "XelaSettings"]

FAMILY = "xela"


class XelaSettings(BackoffSettings):
    """One position of a XELA server (docs/skins.md)."""

    title: Annotated[str, Meta(description="Human-readable name; default the device id.")] | None = None
    url: Annotated[str, Meta(pattern=r"^wss?://", description=(
        "The xela_server's WebSocket (its default port is 5000)."))] = "ws://127.0.0.1:5000"
    position: Annotated[int, Meta(ge=1, le=64, description=(
        "The sensor's position on the server (its key in the messages: 1, 2, ...)."))] = 1
    model: Annotated[Literal["uSPa22", "uSPa44", "uSPa46"], Meta(description=(
        "The sensor model at that position: 2 x 2, 4 x 4 or 4 x 6 taxels."))] = "uSPa44"
    pitch_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Distance between taxel centres, mm (measure yours: docs/skins.md)."))] = 4.7
    forces: Annotated[bool, Meta(description=(
        "Read the server's calibrated forces (N) as the node vectors, and contact forces as their sums; "
        "false: the raw counts, and no force."))] = False
    epsilon: Annotated[float, Meta(gt=0, le=65535, description=(
        "Change of a taxel (its norm) above which it counts as touched: counts, or N with forces; "
        "default 200 counts, 0.05 N."))] | None = None
    baseline_messages: Annotated[int, Meta(ge=1, le=1000, description=(
        "Readings whose mean is the baseline, at start and on tare."))] = 10


@hookimpl
def wott_hub_families() -> list[FamilyInfo]:
    return [FamilyInfo(
        FAMILY,
        "XELA uSkin 3-axis taxels through a running xela_server (WebSocket JSON), one Thing per position: "
        "raw counts (shear and normal) and, when the server is calibrated, forces in N.",
        XelaSettings,
    )]


# XELA's sensors are read by xela_server over CAN; the hub reaches them through the server's
# WebSocket (url), never the USB device. The CAN adapter is listed so a user sees it is there:
# XELA ships an slcan adapter (VScom USB-CAN Plus, per yan-galaxy/xela_server_ros's udev rules),
# an FTDI-based serial device; its own product id was not found in the sources read, so the FTDI
# FT232R's default id (0403:6001) is what is listed. Not tried on a device.
USB_MATCHES = (
    UsbMatch(FAMILY, "tty", "FTDI USB-serial, as XELA's slcan CAN adapter (listed: xela is reached "
             "through xela_server's url)", vendor_id="0403", product_ids=("6001",)),
)


@hookimpl
def wott_hub_usb_devices() -> list[UsbMatch]:
    return list(USB_MATCHES)


@hookimpl
def wott_hub_open_device(config: DeviceConfig) -> Driver:
    return open_xela_device(config)  # the registry calls this only for FAMILY's devices


def open_xela_device(config: DeviceConfig) -> Driver:

    from wott_hub.plugin_api import (
        CoordinateFrame,
        DeviceDescription,
        NodeSignal,
        SkinMesh,
        SkinShape,
        backoff,
        flat_pad,
    )

    from .driver import XelaDriver
    from .protocol import MODELS

    with naming_device(config):
        s = read_settings(XelaSettings, config.settings)
        reconnect = backoff(s)
    rows, cols = MODELS[s.model]
    pad = flat_pad(rows, cols, pitch_mm=s.pitch_mm, clamp_border=False, name=f"xela-{s.model}")
    # taxel 0 is the top left one and rows run down: y flipped, cells turned to face +z again
    nodes = pad.nodes.copy()
    nodes[:, 1] = (rows - 1) * s.pitch_mm - nodes[:, 1]
    mesh = SkinMesh(nodes, pad.cells[:, ::-1], pad.free, name=pad.name)
    epsilon = s.epsilon if s.epsilon is not None else (0.05 if s.forces else 200.0)
    desc = DeviceDescription(
        id=config.id, title=s.title or config.id, family=FAMILY,
        shape=SkinShape("rectangularPrism", length_mm=cols * s.pitch_mm, width_mm=rows * s.pitch_mm),
        material=MATERIALS["ecoflex-00-30"], mesh=mesh, frame=CoordinateFrame(origin_name="bottomLeftTaxel"),
        epsilon_mm=epsilon,
        description=(f"XELA {s.model} ({rows} x {cols} taxels, {s.pitch_mm:g} mm apart) at position "
                     f"{s.position} of {s.url}; " + ("calibrated forces, N" if s.forces else
                                                     "taxel counts (x, y shear, z normal)")),
        node_signal=NodeSignal("force" if s.forces else "taxelSignal"),
    )
    return XelaDriver(desc, url=s.url, position=s.position, model=s.model, forces=s.forces,
                      baseline_messages=s.baseline_messages, backoff=reconnect)
