"""mDNS TXT ``scheme`` follows TLS (issue 17): a hub serving https announces its directory and its
Things with ``scheme=https``, one without TLS with ``scheme=http``.

Zeroconf on 127.0.0.1 only; another process (``wott-hub discover``) browses and reports the TXT
records it resolved, as in test_hub_adoption.py; the certificate is made as docs/security.md says.
"""

from __future__ import annotations

import ssl

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.hub import Hub
from wott_hub.network import DiscoveryConfig
from wott_hub.security import SecurityConfig
from wott_hub.security.tls import write_selfsigned


@pytest.mark.parametrize("tls", [True, False], ids=["tls", "plain"])
def test_announced_records_carry_the_scheme_the_hub_serves(tmp_path, run, tls, discover):
    security = SecurityConfig()
    verify: ssl.SSLContext | bool = True
    if tls:
        cert, key = write_selfsigned(tmp_path / "tls", ["127.0.0.1"])
        security = SecurityConfig(cert=str(cert), key=str(key))
        verify = ssl.create_default_context(cafile=str(cert))
    scheme = "https" if tls else "http"

    async def scenario() -> None:
        cfg = HubConfig(name="scheme-test", http_port=0, ws_port=0, database=str(tmp_path / "hub.db"),
                        discovery=DiscoveryConfig(mdns=True, browse=False), security=security)
        hub = Hub(cfg)
        await hub.start()
        try:
            assert hub.http_url.startswith(f"{scheme}://")
            names = {f"scheme-test {hub.hub_id}", f"hub on scheme-test {hub.hub_id}"}
            rows = await discover(names, 2)
            assert names <= rows.keys(), f"discover never listed both, found {sorted(rows)}"
            directory = rows[f"scheme-test {hub.hub_id}"]
            assert directory["txt"] == {"td": "/.well-known/wot", "type": "Directory", "scheme": scheme}
            thing = rows[f"hub on scheme-test {hub.hub_id}"]
            assert thing["txt"] == {"td": "/wot/hub", "type": "Thing", "scheme": scheme}
            assert thing["port"] == directory["port"] == hub._server.http_port
            # what the records point at answers with that scheme (and the TD's forms use it)
            async with httpx.AsyncClient(verify=verify, timeout=10) as http:
                td = (await http.get(f"{scheme}://127.0.0.1:{thing['port']}{thing['txt']['td']}")).json()
            assert td["id"] == hub._identity.hub_thing_id
            hrefs = [f["href"] for a in td["properties"].values() for f in a["forms"]]
            assert hrefs and all(h.startswith((f"{scheme}://", "ws")) for h in hrefs)
        finally:
            await hub.stop()

    run(scenario(), timeout=120)
