"""The twin in a real headless Chromium against a real hub with simulated devices.

Assertions are on the state the pages keep in ``window.twin`` (what they applied
and drew), polled with deadlines; screenshots go to the test's output folder.
"""

from __future__ import annotations

import time
from urllib.parse import quote

import httpx

from wott_hub.events.record import KIND_EVENT
from wott_hub.hub import demo_devices

FLEET = {d.id for d in demo_devices()} | {"barrel"}


def device_url(twin, thing_id: str) -> str:
    """The device page for a Thing, given by its TD's URL in the directory (as the fleet page links it)."""
    td_url = f"{twin.url}/things/{quote(f'urn:wott-hub:device:{thing_id}', safe='')}"
    return f"{twin.url}/twin/device.html?td={quote(td_url, safe='')}"


def open_device(page, twin, thing_id: str) -> None:
    page.goto(device_url(twin, thing_id))
    page.wait_for_function("window.twin && window.twin.page === 'device' && window.twin.ready", timeout=20_000)


def test_fleet_page_lists_every_demo_device_from_the_directory(twin, page, screenshot):
    page.goto(f"{twin.url}/")
    page.wait_for_function("window.twin && window.twin.ready", timeout=20_000)
    assert page.evaluate("window.twin.source") == "directory"
    keys = sorted(FLEET)
    # every device listed with its health from the hub Thing; the busy barrel shows a rate and an action
    page.wait_for_function(
        """keys => {
          const rows = Object.values(window.twin.devices);
          const byKey = Object.fromEntries(rows.map(r => [r.key, r]));
          return keys.every(k => byKey[k] && byKey[k].health)
            && byKey.barrel.rate > 0 && byKey.barrel.lastAction;
        }""", arg=keys, timeout=15_000)
    rows = page.evaluate("Object.values(window.twin.devices)")
    assert sorted(r["key"] for r in rows) == keys
    assert {r["family"] for r in rows} >= {"scene", *(d.family for d in demo_devices())}
    assert all(r["health"] in ("ok", "degraded", "starting", "ended") for r in rows), rows
    assert page.locator("#fleet tbody tr").count() == len(keys)
    assert page.evaluate("window.twin.hubState") == "ok"
    screenshot(page, "twin-fleet")
    # a row links to the device page of that Thing, by the URL of its TD in the directory
    href = page.locator("#fleet tbody tr[data-key='barrel'] a").get_attribute("href")
    assert f"{twin.url}{href}" == device_url(twin, "barrel")
    assert page.errors == []


def test_device_page_builds_the_mesh_from_the_td_and_deforms_it_live(twin, page, screenshot):
    open_device(page, twin, "barrel")
    nodes = httpx.get(f"{twin.url}/wot/barrel/properties/skinNodes").json()
    cells = httpx.get(f"{twin.url}/wot/barrel/properties/skinCells").json()
    st = page.evaluate("window.twin")
    assert (st["nodes"], st["cells"]) == (nodes["numOfNodes"], cells["numOfCells"]) == (707, 1374)
    trace = page.evaluate("(() => { const d = document.getElementById('skin').data[0];"
                          " return {type: d.type, n: d.x.length, tri: d.i.length}; })()")
    assert trace == {"type": "mesh3d", "n": 707, "tri": 1374}
    assert page.locator("#skin canvas").count() >= 1
    # the scene presses 3 mm: a deep packet is drawn, coloured by intensity, and actions show
    # (the trace's intensities are those of the packet applied last, checked in the same instant)
    page.wait_for_function(
        """() => { const t = window.twin, d = document.getElementById('skin').data[0];
                   return t.drawn && t.drawn.max > 1.5 && t.action
                     && Math.max(...d.intensity) === t.applied.max && t.applied.max > 1.5; }""",
        timeout=15_000)
    assert page.evaluate("window.twin.packets") > page.evaluate("window.twin.frames") > 0  # coalesced
    screenshot(page, "twin-barrel")
    assert page.errors == []


def test_scripted_press_shows_up_in_the_page_within_a_second(twin, page, scene_barrel):
    from wott_hub.examples import example_device

    mesh = example_device("barrel").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[200]]]
    press_s = 3.0
    cfg = scene_barrel("press", loop=False, steps=[
        {"kind": "press", "at": at, "start_s": press_s, "duration_s": 1.0, "depth_mm": 3.0, "radius_mm": 12.0}])
    t0_ms = time.time() * 1000
    twin.call(twin.hub.add_device, cfg)
    twin.call(twin.register)
    press_ms = t0_ms + press_s * 1000  # the device's clock starts after t0: this is no later
    try:
        open_device(page, twin, "press")
        st = page.evaluate("window.twin")
        assert st["packets"] == 0 and time.time() * 1000 < press_ms, "page not ready before the press"
        page.wait_for_function("window.twin.applied && window.twin.applied.max > 0", timeout=press_s * 1000 + 5000)
        st = page.evaluate("window.twin")
        onset = st["onsets"][0]
        assert onset["stamp"] >= press_ms - 50  # the hub stamped the press when the scene made it
        assert st["applied"]["at"] - press_ms < 1000, st["applied"]
        # and the release: the skin is drawn at rest again
        page.wait_for_function("window.twin.drawn && window.twin.last.max === 0 && window.twin.drawn.max === 0",
                               timeout=5000)
    finally:
        twin.call(twin.hub.remove_device, "press")


def test_dropped_sse_connection_resumes_without_loss(twin, page):
    open_device(page, twin, "barrel")
    page.wait_for_function("window.twin.seqs.length >= 20", timeout=10_000)
    before = page.evaluate("window.twin.seqs.length")

    def drop() -> int:
        n = 0
        for h in list(twin.hub.server.ctx.sse):
            if h.request.path == "/wot/barrel/events":
                h.request.connection.stream.close()  # the TCP connection, as a network drop would
                n += 1
        return n

    assert twin.call(drop) == 1
    page.wait_for_function(f"window.twin.reconnects >= 1 && window.twin.seqs.length >= {before + 40}",
                           timeout=10_000)
    seqs = page.evaluate("window.twin.seqs")
    assert len(seqs) == len(set(seqs)) and seqs == sorted(seqs)  # nothing twice, in order

    def served() -> list[int]:
        ring = twin.hub.plane.stream("barrel").ring
        return [r.seq for r in ring if r.kind == KIND_EVENT and seqs[0] <= r.seq <= seqs[-1]]

    assert seqs == twin.call(served)  # nothing lost across the drop
    assert page.evaluate("window.twin.reconnects") == 1 and page.errors == []


def test_replay_control_plays_pauses_resumes_and_goes_live(twin, page):
    open_device(page, twin, "barrel")
    page.wait_for_function("window.twin.replay && window.twin.device === 'barrel'", timeout=10_000)
    page.select_option("#range", "-10s")
    page.click("#play")
    page.wait_for_function("window.twin.replay.state === 'playing' && window.twin.mode === 'replay'"
                           " && window.twin.thing === 'urn:wott-hub:replay:barrel' && window.twin.frames > 2",
                           timeout=15_000)
    assert httpx.get(f"{twin.url}/wot/replay-barrel").status_code == 200
    page.click("#pause")
    page.wait_for_function("window.twin.replay.state === 'paused'", timeout=10_000)
    paused_at = page.evaluate("window.twin.last.stamp")
    assert httpx.get(f"{twin.url}/wot/replay-barrel").status_code == 404  # stopped, not served
    page.click("#play")
    page.wait_for_function(f"window.twin.replay.state === 'playing' && window.twin.last"
                           f" && window.twin.last.stamp > {paused_at}", timeout=15_000)
    page.click("#live")
    page.wait_for_function("window.twin.mode === 'live' && window.twin.thing === 'urn:wott-hub:device:barrel'"
                           " && window.twin.packets > 0", timeout=15_000)
    assert httpx.get(f"{twin.url}/wot/replay-barrel").status_code == 404
    assert page.evaluate("window.twin.replay.error") is None and page.errors == []
