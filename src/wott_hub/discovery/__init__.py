"""mDNS/DNS-SD announcement and browsing of WoT Things and directories, and consumption of what is found.

Hub wiring, in short::

    zc = AsyncZeroconf()                               # or loopback_zeroconf() for a local demo
    announcer = Announcer(zc)
    await announcer.announce_directory("wott-hub", port)             # TD at /.well-known/wot
    await announcer.announce_thing("barrel-1", port, "/things/barrel-1")
    explorer = Explorer(on_found=..., on_updated=..., on_lost=..., claim=registry.claim,
                        own_ids=hub_thing_ids)
    browser = Browser(zc, explorer.service_added, explorer.service_updated, explorer.service_removed,
                      ignore=lambda name: name in announcer.names)
    await browser.start()

Also USB devices (``usb``: udev, pyudev) and the ``[usb]`` table (``usb_config``). The names below
are imported when first used (PEP 562), so reading a config that imports ``usb_config`` does not
load zeroconf.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .announcer import Announcer, default_addresses, loopback_zeroconf
    from .browser import Browser
    from .explorer import Claim, Explorer, FoundThing, td_kind
    from .records import DIRECTORY_SUBTYPE, WOT_TCP, ServiceRecord, instance_name, txt_record

_WHERE = {
    "Announcer": "announcer", "default_addresses": "announcer", "loopback_zeroconf": "announcer",
    "Browser": "browser", "Claim": "explorer", "Explorer": "explorer", "FoundThing": "explorer",
    "td_kind": "explorer", "DIRECTORY_SUBTYPE": "records", "WOT_TCP": "records",
    "ServiceRecord": "records", "instance_name": "records", "txt_record": "records",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "DIRECTORY_SUBTYPE", "WOT_TCP", "Announcer", "Browser", "Claim", "Explorer", "FoundThing",
    "ServiceRecord", "default_addresses", "instance_name", "loopback_zeroconf", "td_kind", "txt_record",
]
