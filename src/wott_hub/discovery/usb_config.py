"""The ``[usb]`` table of the hub config: which families' USB devices the hub adopts when plugged in.

Declared like the other tables (``wott_hub.configspec``). ``adopt`` lists family names; a device
of one of them (``wott_hub_usb_devices``) is opened and served as soon as it is plugged in and
marked disconnected when unplugged (``wott_hub.hub.usb``). Nothing is adopted by default: the
skins' boards (a QT Py, an Arduino, an FTDI cable) serve other uses too, so the hub only lists
them (``wott-hub discover --usb``) until told. That each name is a family an installed plugin
provides, with a match that can be adopted, needs the plugins: ``check_adopt`` (``wott-hub config
check`` and ``run``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Annotated, Any

from wott_hub.configspec import ConfigError, check, doc, read, says, suggest, table_of

__all__ = ["USB_TABLE", "UsbConfig", "check_adopt", "parse_usb"]

Family = Annotated[str, says("a device family name", pattern=r"^[a-z0-9][a-z0-9._-]{0,63}$")]
Families = Annotated[tuple[Family, ...], says("a list of device family names", max_length=64)]


@dataclass(frozen=True)
class UsbConfig:
    adopt: Families = field(default=(), metadata=doc(
        "Device families whose USB devices the hub opens and serves when plugged in (Thing id from the "
        "serial number, e.g. digit-D20001) and marks disconnected when unplugged; others are only "
        "listed (wott-hub discover --usb). Default: none."))

    def __post_init__(self) -> None:
        check(self, USB_TABLE, "[usb]")

    @property
    def enabled(self) -> bool:
        return bool(self.adopt)


USB_TABLE = table_of(UsbConfig, "usb")
"""The ``[usb]`` table as it is written in a file."""


def parse_usb(table: Any, source: str) -> UsbConfig:
    where = f"{source}: [usb]"
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: must be a table")
    t = read(USB_TABLE, table, where)
    cfg = UsbConfig(**{k: getattr(t, k) for k in USB_TABLE.__struct_fields__})
    if len(set(cfg.adopt)) != len(cfg.adopt):
        twice = next(f for f in cfg.adopt if cfg.adopt.count(f) > 1)
        raise ConfigError(f"{where}.adopt: {twice!r} is listed twice")
    return cfg


def check_adopt(cfg: UsbConfig, families: Mapping[str, Any], adoptable: Sequence[str],
                source: str) -> list[str]:
    """One line per family of ``adopt`` that no installed plugin provides (``families``), or that no USB
    match can adopt (``adoptable``: the families of the matches with a setting)."""
    out = []
    for i, name in enumerate(cfg.adopt):
        where = f"{source}: [usb].adopt[{i}]"
        if name not in families:
            known = ", ".join(sorted(set(adoptable) & set(families))) or "none"
            out.append(f"{where}: unknown family {name!r}{suggest(name, families)} "
                       f"(families with USB devices: {known})")
        elif name not in adoptable:
            out.append(f"{where}: family {name!r} declares no USB device the hub can adopt "
                       "(its plugin implements no wott_hub_usb_devices, or lists its devices only)")
    return out
