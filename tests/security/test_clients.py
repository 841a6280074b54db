"""The project's own clients use the same credentials against a protected hub (loopback, tokens
configured: credentials are then required on loopback too): ``wot-remote`` with a ``token``
setting, ``register_to`` with an admin token, ``wott_client.Client(token=...)``."""

from __future__ import annotations

import httpx

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig
from wott_hub.network.config import DirectoryConfig, Registration
from wott_hub.plugins import DeviceConfig
from wott_hub.security import Scope, SecurityConfig, TokenFile


def test_wot_remote_and_register_to_authenticate_to_a_protected_hub(tmp_path, hub_thread, press_scene,
                                                                      wait_for, run):
    f = TokenFile(tmp_path / "tokens.json")
    read = f.create("mirror", Scope.READ)[0]
    admin = f.create("registrar", Scope.ADMIN)[0]
    protected = hub_thread(HubConfig(http_port=0, ws_port=0, history=False, devices=(press_scene("pad"),),
                                     discovery=DiscoveryConfig.off(), name="protected",
                                     security=SecurityConfig(tokens_file=str(f.path)))).start()
    try:
        td_url = protected.hub.td_url("pad")
        assert httpx.get(td_url).status_code == 401
        from wott_client import Client

        with Client(token=read) as c:  # the Python client (client/): TD, property, SSE frames
            thing = c.thing(td_url)
            assert thing.read_property("skinShape")["shapeType"] == "rectangularPrism"
            assert next(iter(thing.frames())) is not None
        remote = DeviceConfig("far-pad", "wot-remote", {"url": td_url, "token": read})
        mirror = hub_thread(HubConfig(
            http_port=0, ws_port=0, history=False, devices=(remote,), discovery=DiscoveryConfig.off(),
            name="mirror", directory=DirectoryConfig(register_to=(Registration(protected.url + "/", admin),),
                                                     ttl_s=60.0))).start()
        try:
            dev = mirror.hub.devices["far-pad"]
            run(wait_for(lambda: dev.driver.packets > 0, 20, "frames from the protected hub"))
            listed = lambda: [t["id"] for t in httpx.get(  # noqa: E731
                protected.url + "/things", headers={"Authorization": f"Bearer {read}"}).json()]
            run(wait_for(lambda: any(":far-pad" in i or "far-pad" in i for i in listed()), 20,
                         "the mirror's TDs registered into the protected hub's directory"))
        finally:
            mirror.stop()
    finally:
        protected.stop()
