"""The twin draws geometry (issue 29), in a real headless Chromium: the displaced surface moved by each
node's skinDisplacement vector (not only recoloured), shear as arrows, contact forces as arrows, and a
camera device's live raw image."""

from __future__ import annotations

from urllib.parse import quote

import pytest

READY = "window.twin && window.twin.page === 'device' && window.twin.ready"

# the vertex positions and rest positions the page draws, and the largest move of a vertex from rest
GEOMETRY = """() => { const d = document.getElementById('skin').data[0], r = d.rest;
  const x = d.x, y = d.y, z = d.z; let moved = 0, at = -1;
  for (let k = 0; k < x.length; k++) {
    const m = Math.hypot(x[k] - r[3 * k], y[k] - r[3 * k + 1], z[k] - r[3 * k + 2]);
    if (m > moved) { moved = m; at = k; }
  }
  return {moved, at, n: x.length}; }"""


def _url(hub, thing_id: str) -> str:
    td_url = f"{hub.url}/things/{quote(hub.hub._identity.device_id(thing_id), safe='')}"
    return f"{hub.url}/twin/device.html?td={quote(td_url, safe='')}"


@pytest.fixture(scope="module")
def barrel(twin, browser, open_page, wait):
    page = open_page(browser)
    page.goto(_url(twin, "barrel"))
    wait(page, READY, timeout=20_000)
    yield page
    page.close()


def test_vertices_move_by_the_nodes_vectors_and_shear_and_forces_are_arrows(barrel, wait, screenshot):
    page = barrel
    assert page.evaluate("window.twin.vectors") is True  # the TD declares skinDisplacement
    # the scene presses 4 mm: at true scale (the default), a vertex has moved by about that much, and
    # by its own vector: the position is rest + vector for a node the last packet drew
    wait(page, f"(() => {{ const t = window.twin, g = ({GEOMETRY})();"
               " return t.drawn && t.drawn.max > 3 && g.moved > 3; })()", timeout=15_000)
    got = page.evaluate(f"""() => {{ const g = ({GEOMETRY})(), s = window.twin.skinState();
      return {{...g, vec: s.vec(g.at), rest: s.rest(g.at), pos: s.pos(g.at), scale: s.scale}}; }}""")
    assert got["n"] == 707 and got["scale"] == 1
    for axis in range(3):
        assert abs(got["pos"][axis] - (got["rest"][axis] + got["vec"][axis])) < 1e-3
    # the slide drags the skin along: shear arrows drawn, and a force arrow per contact
    wait(page, "window.twin.shear && window.twin.shear.n > 0 && window.twin.shear.max > 0.05"
               " && window.twin.forces >= 1", timeout=15_000)
    screenshot(page, "twin-barrel-shear")
    # 5x: the same node five times as far from rest
    page.select_option("#exaggerate", "5")
    wait(page, f"(() => ({GEOMETRY})().moved > 15)()", timeout=15_000)
    page.select_option("#exaggerate", "1")
    page.select_option("#arrows", "0")  # shear arrows off
    wait(page, "window.twin.shear && window.twin.shear.n === 0", timeout=15_000)
    page.select_option("#arrows", "5")
    assert page.errors == []


def test_a_camera_devices_page_shows_its_live_raw_image(fleet, browser, open_page, wait):
    page = open_page(browser)
    try:
        page.goto(_url(fleet, "flatpad-1"))
        wait(page, READY, timeout=20_000)
        assert page.evaluate("document.getElementById('raw-panel').hidden") is False
        src = page.evaluate("window.twin.raw.src")
        assert "/properties/rawImage/stream" in src and "maxRate=" in src
        # the browser decodes the multipart stream's JPEG parts: the camera's 640 x 480
        wait(page, "(() => { const i = document.getElementById('raw-image');"
                   " return i.naturalWidth === 640 && i.naturalHeight === 480; })()",
             timeout=30_000)
        page.goto(_url(fleet, "barrel"))  # a scene device: no camera, no panel
        wait(page, READY, timeout=20_000)
        assert page.evaluate("document.getElementById('raw-panel').hidden") is True
        assert page.errors == []
    finally:
        page.close()
