"""The hub's side of ``network.HubPort``: the few things the directory, registrations and mDNS
may use, taken from the servient, the history and the devices."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import tornado.web
    from sqlalchemy import Engine

    from wott_hub.config import HubConfig
    from wott_hub.plugins.model import DeviceConfig
    from wott_hub.servient import HubServer, ServedThing

    from .devices import DeviceRuntime, Devices
    from .identity import HubIdentity
    from .recording import HubHistory

__all__ = ["NetworkPort"]


class NetworkPort:
    def __init__(self, config: HubConfig, server: HubServer, history: HubHistory, devices: Devices,
                 identity: HubIdentity) -> None:
        self._config = config
        self._identity = identity
        self._server = server
        self._history = history
        self._devices = devices

    @property
    def name(self) -> str:
        return self._config.name

    @property
    def hub_id(self) -> str:
        return self._identity.id

    @property
    def id_prefix(self) -> str:
        return self._identity.prefix

    @property
    def hub_thing_id(self) -> str:
        return self._identity.hub_thing_id

    @property
    def host(self) -> str:
        return self._config.host

    @property
    def http_url(self) -> str:
        return self._server.layout.http_base

    @property
    def directory_credential(self) -> str | None:
        """The hub's in-process token for its embedded directory while the gate checks clients
        (``wott_hub.security``); None in open mode."""
        policy = self._server.policy
        return policy.internal_token if policy.enforced else None

    @property
    def directory_td_security(self) -> dict[str, Any] | None:
        """The schemes the gate enforces on the embedded directory's routes, for its own TD
        (``wott_directory.selftd``): the hub's bearer token (its scopes) on every form, header or
        query on the event streams; None in open mode (the directory's own settings then)."""
        from wott_hub.security.policy import BEARER, BEARER_EITHER

        policy = self._server.policy
        if not policy.enforced:
            return None
        return {"securityDefinitions": policy.security_definitions(), "security": [BEARER],
                "streams": [BEARER_EITHER]}

    @property
    def http_port(self) -> int:
        return self._server.http_port

    @property
    def http_app(self) -> tornado.web.Application:
        app: tornado.web.Application = self._server.http.app
        return app

    @property
    def engine(self) -> Engine | None:
        return self._history.engine

    def td_url(self, thing_id: str) -> str:
        return self._server.td_url(thing_id)

    def add_handlers(self, rules: Sequence[tuple[Any, ...]]) -> None:
        self._server.add_handlers(rules)

    def served(self) -> list[ServedThing]:
        return list(self._server.things)

    def is_served(self, thing_id: str) -> bool:
        return thing_id in self._server.things.by_id

    def listen(self, on_expose: Callable[[ServedThing], None],
               on_remove: Callable[[ServedThing], None]) -> None:
        self._server.on_expose.append(on_expose)
        self._server.on_remove.append(on_remove)

    async def add_device(self, dcfg: DeviceConfig) -> DeviceRuntime:
        return await self._devices.add_device(dcfg)

    async def remove_device(self, device_id: str) -> None:
        await self._devices.remove(device_id)

    def device(self, device_id: str) -> DeviceRuntime | None:
        return self._devices.running.get(device_id)
