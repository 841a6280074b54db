"""The built-in family ``wot-remote``: adopt a tactile device that already speaks WoT.

Discovery hands every foreign TD to ``Registry.claim``; this family claims the
ones that carry the Tactile affordances the hub needs (``skinNodes``,
``skinCells`` readable over HTTP, ``skinDeformedDetection`` over SSE) and
re-exposes them with the hub's own Tactile TD through
``wott_hub.drivers.remote.RemoteWoTDriver``. A device can also be configured
by hand with the URL of its TD.

A Thing that is itself a re-exposure (``tac:family`` ``wot-remote``) is left
alone: the original is adopted instead, and two hubs can never re-expose each
other's copies forever. Third-party plugins are asked before this family
(pluggy calls later registrations first), so one that knows a device better
wins it.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar

from slugify import slugify

from wott_hub.drivers.remote import FAMILY, MAX_NODES, MAX_TD_BYTES, RemoteWoTDriver, tactile_affordances

from .model import DeviceConfig, FamilyInfo
from .naming import naming_device
from .settings import Meta, SettingsModel, read_settings, settings_schema

__all__ = ["FAMILY", "SCHEMA", "RemoteSettings", "claim_td", "family", "open_device"]

class RemoteSettings(SettingsModel):
    """A ``wot-remote`` device's settings, declared once; ``SCHEMA`` is derived for docs and the
    registry. Exactly one of ``url`` and ``td`` is given."""

    json_schema_extra: ClassVar[dict[str, Any]] = {"oneOf": [{"required": ["url"]}, {"required": ["td"]}]}

    url: Annotated[str, Meta(
        description="URL of the device's Thing Description (http or https).")] | None = None
    td: Annotated[dict[str, Any], Meta(
        description="The device's TD itself (what discovery passes).")] | None = None
    title: Annotated[str, Meta(
        description="Title of the re-exposed device (default: the TD's).")] | None = None
    token: Annotated[str, Meta(min_length=1, description=(
        "Bearer token for a device or hub whose TD declares bearer security "
        "(another wott-hub: a read token; docs/security.md)."))] | None = None
    timeout_s: Annotated[float, Meta(gt=0, le=3600, description=(
        "Connect and property-read timeout, seconds."))] = 5.0
    idle_timeout_s: Annotated[float, Meta(gt=0, le=86_400, description=(
        "Reconnect (resuming) after this long without a byte on the "
        "event stream; a wott-hub sends a heartbeat every 15 s."))] = 60.0
    epsilon_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Deformation threshold ε; default: the TD's tac:epsilon less one "
        "rounding step of the packets."))] | None = None
    thickness_mm: Annotated[float, Meta(gt=0, le=100, description=(
        "Skin thickness for the force model (not in a Tactile TD)."))] = 3.0
    max_nodes: Annotated[int, Meta(ge=1, le=1_000_000, description=(
        "Largest mesh adopted, nodes (at most 4 cells per node); a device with more is refused "
        "before its mesh is built. Devices found by discovery get [discovery] max_adopted_nodes."
    ))] = MAX_NODES
    max_td_bytes: Annotated[int, Meta(ge=1024, le=64 * 1024 * 1024, description=(
        "Largest TD read from the device, bytes (with url; a TD given inline is the config's)."
    ))] = MAX_TD_BYTES


SCHEMA: dict[str, Any] = settings_schema(RemoteSettings)


def family() -> FamilyInfo:
    return FamilyInfo(FAMILY, "A tactile device that speaks WoT itself (Tactile TD over HTTP + SSE), "
                              "found by discovery or given by the URL of its TD.", RemoteSettings)


def claim_td(td: dict[str, Any]) -> DeviceConfig | None:
    if td.get("tac:family") == FAMILY:
        return None  # a re-exposure: adopt the original, not a copy
    if tactile_affordances(td) is None:
        return None
    name = td.get("title") if isinstance(td.get("title"), str) else None
    device_id = slugify(name or str(td.get("id") or ""), max_length=60) or "wot-device"
    return DeviceConfig(device_id, FAMILY, {"td": td})


def open_device(config: DeviceConfig) -> RemoteWoTDriver:
    with naming_device(config):
        s = read_settings(RemoteSettings, config.settings)
    return RemoteWoTDriver(config.id, td=s.td, url=s.url, title=s.title, timeout_s=s.timeout_s,
                           idle_timeout_s=s.idle_timeout_s, epsilon_mm=s.epsilon_mm,
                           thickness_mm=s.thickness_mm, token=s.token, max_nodes=s.max_nodes,
                           max_td_bytes=s.max_td_bytes)
