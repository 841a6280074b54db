"""What the network side needs of the hub, and nothing more: the port it is given.

The directory, the registrations and mDNS (``HubNetwork``) are built by the
hub with a ``HubPort``; they never import the hub. What they may do: mount
routes on the hub's HTTP port, open the directory on the hub's database, list
and follow the Things the hub serves, and add, remove and find the devices
discovery adopts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    import tornado.web
    from sqlalchemy import Engine

    from wott_hub.drivers.base import Health
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.servient import ServedThing

__all__ = ["DeviceDriver", "HubDevice", "HubPort"]


class DeviceDriver(Protocol):
    """A device's driver (or its worker proxy) as discovery uses it: marked gone; re-targeted when it
    is ``wott_hub.drivers.base.Retargetable``."""

    def set_health(self, state: Health, reason: str = "") -> None: ...


class HubDevice(Protocol):
    """A device the hub serves, as discovery sees it: its driver (re-targeted or marked gone)."""

    @property
    def driver(self) -> DeviceDriver: ...


class HubPort(Protocol):
    @property
    def name(self) -> str:
        """The hub's name (``[hub] name``): mDNS instance names, the directory's title."""
        ...

    @property
    def hub_id(self) -> str:
        """The hub's id (``wott_hub.hub.identity``): in its mDNS host and instance names."""
        ...

    @property
    def id_prefix(self) -> str:
        """What every Thing id of this hub starts with (``urn:wott-hub:<hub-id>:``)."""
        ...

    @property
    def hub_thing_id(self) -> str:
        """The TD id of the hub Thing: the one a directory is checked for before registering."""
        ...

    @property
    def host(self) -> str:
        """The address the hub listens on (mDNS interfaces, who may write to the directory)."""
        ...

    @property
    def http_url(self) -> str: ...

    @property
    def directory_credential(self) -> str | None:
        """The token the embedded directory requires of every client while the hub's gate checks
        clients' scoped tokens (the gate hands it on for them); None when the hub runs open."""
        ...

    @property
    def directory_td_security(self) -> dict[str, Any] | None:
        """The security the embedded directory's own TD declares (``securityDefinitions``,
        ``security``, ``streams``) when the hub's gate enforces tokens; None: the directory's own."""
        ...

    @property
    def http_port(self) -> int: ...

    @property
    def http_app(self) -> tornado.web.Application:
        """The hub's HTTP application (the directory's router replays held requests into it)."""
        ...

    @property
    def engine(self) -> Engine | None:
        """The history database's SQLAlchemy engine (the directory's tables are there); None: off."""
        ...

    def td_url(self, thing_id: str) -> str: ...

    def add_handlers(self, rules: Sequence[tuple[Any, ...]]) -> None:
        """Mount routes on the hub's HTTP port."""
        ...

    def served(self) -> list[ServedThing]:
        """Every Thing the hub serves now."""
        ...

    def is_served(self, thing_id: str) -> bool: ...

    def listen(self, on_expose: Callable[[ServedThing], None],
               on_remove: Callable[[ServedThing], None]) -> None:
        """Be told of every Thing the hub starts or stops serving, whoever exposed it."""
        ...

    async def add_device(self, dcfg: DeviceConfig) -> HubDevice:
        """Open and serve a device (``wott_hub.plugins.DeviceConfig``); ``WottHubError`` if it cannot."""
        ...

    async def remove_device(self, device_id: str) -> None: ...

    def device(self, device_id: str) -> HubDevice | None: ...
