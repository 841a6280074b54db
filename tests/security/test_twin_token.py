"""The twin (web/static) against a protected hub: the token from the URL fragment or typed when
the hub refuses, kept in sessionStorage, sent on fetch (header), EventSource and WebSocket
(``?access_token=``). Debian's chromium driven by Playwright, as tests/web does."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig
from wott_hub.security import Scope, SecurityConfig, TokenFile

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
LIVE = """() => window.twin && window.twin.ready && Object.values(window.twin.devices)
                 .some(r => r.key === 'pad' && r.health && r.rate > 0)"""


@pytest.fixture(scope="module")
def protected(tmp_path_factory, hub_thread, press_scene):
    d = tmp_path_factory.mktemp("twin")
    token = TokenFile(d / "tokens.json").create("browser", Scope.READ)[0]
    hub = hub_thread(HubConfig(http_port=0, ws_port=0, database=str(d / "hub.db"), history_batch_ms=20,
                               devices=(press_scene("pad"),), discovery=DiscoveryConfig.off(),
                               security=SecurityConfig(tokens_file=str(d / "tokens.json")))).start()
    yield hub, token
    hub.stop()


def test_the_twin_takes_the_token_from_the_fragment_or_asks_for_it(protected):
    assert Path(CHROMIUM).exists(), "the browser tests need Debian's chromium (.ci/run installs it)"
    from playwright.sync_api import sync_playwright

    hub, token = protected
    with sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(tempfile.mkdtemp(prefix="wott-sec-"), headless=True,
                                                   executable_path=CHROMIUM, args=ARGS)
        try:
            page = ctx.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{hub.url}/#access_token={token}")
            page.wait_for_function(LIVE, timeout=20_000)
            assert page.evaluate("location.hash") == ""  # not left in the address bar or history
            assert page.evaluate("sessionStorage.getItem('wott-hub-token')") == token

            asked = ctx.new_page()  # a new tab: no token yet; the hub's 401 makes the page ask
            asked.on("dialog", lambda dialog: dialog.accept(token))
            asked.goto(f"{hub.url}/")
            asked.wait_for_function(LIVE, timeout=20_000)
            assert errors == []
        finally:
            ctx.close()
