"""The hub on the network: its TD directory, registrations into other directories, mDNS.

``HubNetwork`` (``hub.network``) is built by the hub with a ``HubPort``
(port.py) and started once the history database is open: it serves the
embedded W3C WoT Thing Description Directory at the host root, keeps every
Thing the hub exposes in it (and in
the ``register_to`` directories, with a ttl), announces the directory and the
Things on mDNS, and adopts the tactile WoT devices that discovery finds.
"""

from typing import Any

from .config import DirectoryConfig, DiscoveryConfig, Registration
from .port import HubPort

__all__ = ["DirectoryConfig", "DiscoveryConfig", "HubNetwork", "HubPort", "Registration"]


def __getattr__(name: str) -> Any:
    if name == "HubNetwork":  # the directory, zeroconf and tornado only when a hub is built
        from .hub_network import HubNetwork

        return HubNetwork
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
