"""The device page in a real headless Chromium: mesh from the TD, live deformation, resume, replay.

Assertions are on the state the page keeps in ``window.twin`` (what it applied and
drew), polled with deadlines; screenshots go to the test's output folder.
"""

from __future__ import annotations

import time
from urllib.parse import quote

import httpx
import pytest

from wott_hub.events.record import KIND_EVENT

READY = "window.twin && window.twin.page === 'device' && window.twin.ready"


def device_url(twin, thing_id: str) -> str:
    """The device page for a Thing, given by its TD's URL in the directory (as the fleet page links it)."""
    td_url = f"{twin.url}/things/{quote(twin.hub._identity.device_id(thing_id), safe='')}"
    return f"{twin.url}/twin/device.html?td={quote(td_url, safe='')}"


@pytest.fixture(scope="module")
def barrel(twin, browser, open_page, wait):
    """One device page on the busy barrel, shared by the tests of this module (in order)."""
    page = open_page(browser)
    page.goto(device_url(twin, "barrel"))
    wait(page, READY, timeout=20_000)
    yield page
    page.close()


def test_device_page_builds_the_mesh_from_the_td_and_deforms_it_live(twin, barrel, screenshot, wait):
    page = barrel
    nodes = httpx.get(f"{twin.url}/wot/barrel/properties/skinNodes").json()
    cells = httpx.get(f"{twin.url}/wot/barrel/properties/skinCells").json()
    st = page.evaluate("window.twin")
    assert (st["nodes"], st["cells"]) == (nodes["numOfNodes"], cells["numOfCells"]) == (707, 1374)
    trace = page.evaluate("(() => { const d = document.getElementById('skin').data[0];"
                          " return {type: d.type, n: d.x.length, tri: d.i.length}; })()")
    assert trace == {"type": "mesh", "n": 707, "tri": 1374}
    assert page.locator("#skin canvas").count() >= 1
    # the scene presses 4 mm: a deep packet is drawn, coloured by intensity, and actions show.
    # A deep packet applied: hold that picture (the page's "hold" box) in the same instant, so nothing
    # newer is applied; its draw reaches the screen at the next animation frame, and the trace's
    # intensities are that packet's. (While packets come at 120 Hz a frame applies a new one before
    # the last one's "drawn" stamp: waiting for both to be equal without holding was luck.)
    wait(page,
        """() => { const t = window.twin;
                   const deep = t.applied && t.applied.max > 3 && t.contacts > 0 && t.action;
                   if (deep) t.freeze = document.getElementById('freeze').checked = true;
                   return deep; }""",
        timeout=15_000)
    wait(page,
        """() => { const t = window.twin, d = document.getElementById('skin').data[0];
                   return t.drawn && t.drawn.seq === t.applied.seq
                     && Math.max(...d.intensity) === t.applied.max; }""",
        timeout=5_000)
    assert page.evaluate("window.twin.drawn.max") > 3
    screenshot(page, "twin-barrel")
    page.uncheck("#freeze")
    assert page.evaluate("window.twin.freeze") is False
    assert page.evaluate("window.twin.packets") > page.evaluate("window.twin.frames") > 0  # coalesced
    # none lost: every packet was drawn or coalesced into a later draw (or waits for the next one),
    # and a draw uploads only the nodes that changed, not the whole mesh
    acc = page.evaluate("window.__twinStats.snapshot()")
    assert acc["packets"] == acc["coalesced"] + acc["waiting"] + acc["dropped"] and acc["dropped"] == 0
    assert acc["draws"] > 1 and acc["uploaded"] < acc["draws"] * 707
    assert page.errors == []


def test_skin_geometry_triangulates_quads_and_dents_along_the_inward_normal(barrel):
    """skin.js on the flat pad's TD values (quads, normal +z): what the page does to any packet."""
    from wott_hub.examples import example_device
    from wott_hub.td.builder import static_property_values

    values = static_property_values(example_device("flat"))
    got = barrel.evaluate(
        """async ([nodes, cells]) => {
          const {Skin} = await import('/twin/skin.js');
          const s = new Skin(nodes, cells);
          const max = s.apply({arrayOfDeformedNodes: [{deformedNodeID: 5, deformedNodeIntensity: 1.5},
                                                      {deformedNodeID: 99999, deformedNodeIntensity: 9}]}, 2);
          return {n: s.n, tri: s.i.length, nz: Array.from(s.normals).filter((v, k) => k % 3 === 2),
                  z5: s.z[5], rest5: s.rest[17], max, others: s.intensity.filter(v => v > 0).length};
        }""", [values["skinNodes"], values["skinCells"]])
    assert got["n"] == 256 and got["tri"] == 2 * 225  # each quad as two triangles
    assert all(abs(v - 1) < 1e-9 for v in got["nz"])  # outward = +z for the pad
    assert got["max"] == 1.5 and got["others"] == 1  # an unknown node id is ignored
    assert abs(got["z5"] - (got["rest5"] - 2 * 1.5)) < 1e-9  # 1.5 mm into the skin, shown at 2x


def test_contacts_are_drawn_by_force_with_their_ids(barrel):
    """render3d.js on the flat pad's TD values (issue 31): a 45 N press and a 0.5 N side lobe were drawn
    the same; now the diamond's size and colour follow the force, each carries its contact id, and a
    label is made once per id and let go when the contact goes."""
    from wott_hub.examples import example_device
    from wott_hub.td.builder import static_property_values

    values = static_property_values(example_device("flat"))
    got = barrel.evaluate(
        """async ([nodes, cells]) => {
          const {Skin} = await import('/twin/skin.js');
          const {SkinView} = await import('/twin/render3d.js');
          const box = document.createElement('div');
          box.style.cssText = 'width: 200px; height: 150px';
          document.body.appendChild(box);
          const view = new SkinView(box, new Skin(nodes, cells));
          view.setContacts([{x: 5, y: 5, z: 0, force: 45, id: 3}, {x: 15, y: 15, z: 0, force: 0.5, id: 4}]);
          const two = view.marks, labels2 = view.labels.size;
          view.setContacts([{x: 6, y: 5, z: 0, force: 40, id: 3}]);
          const one = view.marks, labels1 = view.labels.size;
          const shown = view.markers.filter((m) => m.m.visible).length;
          view.render();
          view.dispose();
          box.remove();
          return {two, one, labels2, labels1, shown};
        }""", [values["skinNodes"], values["skinCells"]])
    press, lobe = got["two"]
    assert (press["id"], lobe["id"]) == (3, 4)
    assert press["scale"] == 1.0 and lobe["scale"] < 0.5  # the lobe a speck beside the press
    assert press["colour"] != lobe["colour"] and press["colour"][0] > press["colour"][2]  # red, not pale
    assert got["labels2"] == 2 and got["labels1"] == 1 and got["shown"] == 1  # id 4's label let go
    assert got["one"][0]["id"] == 3 and 0.9 < got["one"][0]["scale"] <= 1.0
    assert barrel.errors == []


def test_the_live_page_draws_the_hubs_contacts_with_their_ids(barrel, wait):
    """The scene barrel's press: the page reads contactIds from contactInformation and labels them."""
    # one snapshot, taken when the condition holds (the press may be released a moment later)
    st = wait(barrel, "(() => { const t = window.twin;"
                      " if (!(t.marks.length > 0 && t.contactIds.length > 0"
                      "       && t.contactIds.every(i => Number.isInteger(i)))) return false;"
                      " return {ids: [...t.contactIds], marks: t.marks.map(m => ({...m})),"
                      "         title: document.getElementById('contacts').title}; })()",
              timeout=15_000).json_value()
    assert [m["id"] for m in st["marks"]] == st["ids"] and all(i >= 1 for i in st["ids"])
    assert st["title"].startswith(f"#{st['ids'][0]}: ")


def test_dropped_sse_connection_resumes_without_loss(twin, barrel, wait):
    page = barrel
    wait(page, "window.twin.seqs.length >= 20", timeout=10_000)
    before = page.evaluate("window.twin.seqs.length")
    reconnects = page.evaluate("window.twin.reconnects")

    def drop() -> int:
        n = 0
        for h in list(twin.hub._server.ctx.sse):
            if h.request.path == "/wot/barrel/events":
                h.request.connection.stream.close()  # the TCP connection, as a network drop would
                n += 1
        return n

    assert twin.call(drop) == 1
    wait(page, f"window.twin.reconnects > {reconnects}"
                           f" && window.twin.seqs.length >= {before + 40}", timeout=10_000)
    seqs = page.evaluate("window.twin.seqs")
    assert len(seqs) == len(set(seqs)) and seqs == sorted(seqs)  # nothing twice, in order

    def served() -> list[int]:
        ring = twin.hub._plane.stream("barrel").ring
        return [r.seq for r in ring if r.kind == KIND_EVENT and seqs[0] <= r.seq <= seqs[-1]]

    assert seqs == twin.call(served)  # nothing lost across the drop
    assert page.evaluate("window.twin.reconnects") == reconnects + 1 and page.errors == []


def test_replay_control_plays_pauses_resumes_and_goes_live(twin, barrel, wait):
    page = barrel
    wait(page, "window.twin.replay && window.twin.device === 'barrel'", timeout=10_000)
    page.select_option("#range", "-10s")
    page.click("#play")
    wait(page, "window.twin.replay.state === 'playing' && window.twin.mode === 'replay'"
                           f" && window.twin.thing === '{twin.hub._identity.replay_id('barrel')}'"
                           " && window.twin.frames > 2",
                           timeout=15_000)
    assert httpx.get(f"{twin.url}/wot/replay-barrel").status_code == 200
    page.click("#pause")
    wait(page, "window.twin.replay.state === 'paused'", timeout=10_000)
    paused_at = page.evaluate("window.twin.last.stamp")
    assert httpx.get(f"{twin.url}/wot/replay-barrel").status_code == 404  # stopped, not served
    page.click("#play")
    wait(page, f"window.twin.replay.state === 'playing' && window.twin.last"
                           f" && window.twin.last.stamp > {paused_at}", timeout=15_000)
    page.click("#live")
    live_id = twin.hub._identity.device_id("barrel")
    wait(page, f"window.twin.mode === 'live' && window.twin.thing === '{live_id}'"
                           " && window.twin.packets > 0", timeout=15_000)
    assert httpx.get(f"{twin.url}/wot/replay-barrel").status_code == 404
    assert page.evaluate("window.twin.replay.error") is None and page.errors == []


def test_scripted_press_shows_up_in_the_page(twin, page, scene_barrel, wait):
    """A scene pressing every 2.75 s from a known start: the page applies and draws a press that
    comes after it is ready (received, then applied, then drawn), then draws the skin at rest again.

    How soon after the press the page shows it is a timing (``bench twin``); a test on a busy machine
    asserts only what a defect breaks: the press reaches the page, in order, before the release."""
    from wott_hub.examples import example_device

    mesh = example_device("barrel").mesh
    at = [round(float(v), 3) for v in mesh.nodes[mesh.free_indices[200]]]
    cfg = scene_barrel("press", steps=[{"kind": "press", "at": at, "start_s": 2.0, "duration_s": 0.5,
                                        "depth_mm": 3.0, "radius_mm": 12.0}])
    period_ms = (2.5 + 0.25) * 1000  # the scene's duration: last step's end and a rest tail
    t0_ms = time.time() * 1000
    twin.call(twin.hub.add_device, cfg)
    try:
        page.goto(device_url(twin, "press"))
        wait(page, f"{READY} && window.twin.streamState === 'open'", timeout=60_000)
        ready_ms = time.time() * 1000
        # the device's clock starts after t0, so each press is no earlier than computed here
        press_ms = t0_ms + 2000
        while press_ms < ready_ms + 200:
            press_ms += period_ms
        onset = wait(page,
            "t => window.twin.onsets.find(o => o.stamp >= t && o.drawn !== null) || null",
            arg=press_ms - 50, timeout=60_000).json_value()
        assert onset["applied"] is not None and onset["received"] <= onset["applied"] <= onset["drawn"]
        # and the release: the skin is drawn at rest again
        wait(page, "window.twin.drawn && window.twin.last.max === 0"
                               " && window.twin.drawn.max === 0", timeout=60_000)
        assert page.errors == []
    finally:
        twin.call(twin.hub.remove_device, "press")
