"""A browser page with nothing but ``new EventSource(url).onmessage`` receives every kind of event.

Chromium (Debian's, driven by Playwright as in tests/web) opens, from the SSE
forms of the served TDs, one stream per affordance: a device's two events, its
observed ``contactInformation``, the hub Thing's ``healthChange``. Before this
issue ``onmessage`` never fired: every message was named. The stream of all of
a Thing's events keeps the names (its reader must tell the events apart), so
there ``onmessage`` stays silent and ``addEventListener(name)`` receives them.
"""

from __future__ import annotations

import httpx

_OPEN = """(urls) => {
  window.got = {};
  window.sources = [];
  for (const [key, url] of Object.entries(urls)) {
    const got = (window.got[key] = {n: 0, named: 0, data: [], id: null});
    const es = new EventSource(url);
    es.onmessage = (e) => {
      got.n++;
      if (got.data.length < 20) got.data.push(JSON.parse(e.data));
      got.id = e.lastEventId;
    };
    if (key === "all") es.addEventListener("actionDetection", () => got.named++);
    window.sources.push(es);
  }
}"""


def _sse_href(forms: list[dict], op: str) -> str:
    return next(f["href"] for f in forms if op in f["op"] and f.get("subprotocol") == "sse")


def test_a_page_with_plain_onmessage_receives_events_of_each_kind(fleet, browser, scripted_press):
    url = fleet.url
    catalogue = httpx.get(f"{url}/wot").json()
    device = next(i for i in catalogue if i != "hub")
    td = httpx.get(f"{url}/wot/{device}").json()
    hub = httpx.get(f"{url}/wot/hub").json()
    # one stream per kind (a browser holds 6 HTTP/1.1 connections per host): the paper's two events
    urls = {name: _sse_href(td["events"][name]["forms"], "subscribeevent")
            for name in ("actionDetection", "skinDeformedDetection")}
    urls["contactInformation"] = _sse_href(td["properties"]["contactInformation"]["forms"], "observeproperty")
    urls["healthChange"] = _sse_href(hub["events"]["healthChange"]["forms"], "subscribeevent")
    urls["all"] = _sse_href(td["forms"], "subscribeallevents")

    page = browser.new_page()
    try:
        page.goto(f"{url}/healthz")
        page.evaluate(_OPEN, urls)
        page.wait_for_function("window.sources.every((s) => s.readyState === EventSource.OPEN)",
                               timeout=15_000)
        scripted_press("late-browser")  # joins, presses, ends: healthChange
        page.wait_for_function(  # another device's health may change first (a shared fleet)
            "Object.entries(window.got).every(([k, g]) => k === 'all' ? g.named > 0 : g.n > 0)"
            " && window.got.healthChange.data.some((h) => h.device === 'late-browser')",
            timeout=20_000)
        page.evaluate("window.sources.forEach((s) => s.close())")
        got = page.evaluate("window.got")
    finally:
        page.close()

    assert set(got["actionDetection"]["data"]) <= set(td["events"]["actionDetection"]["data"]["enum"])
    assert all(p["numOfDeformedNodes"] == len(p["arrayOfDeformedNodes"])
               for p in got["skinDeformedDetection"]["data"])
    assert all("numOfContacts" in v for v in got["contactInformation"]["data"])
    assert "late-browser" in {h["device"] for h in got["healthChange"]["data"]}
    assert all(int(g["id"]) > 0 for k, g in got.items() if k != "all")  # ids: resume keeps working
    assert got["all"]["n"] == 0 and got["all"]["named"] > 0  # several affordances: named messages
