"""The marker path: dark dots on the real Mini background (rendered by ``wott_vision.render``, their
motion known) tracked against the rest frame -> skinDisplacement; a gel without markers declares none."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from wott_driver_gel.evaluation import write_recording
from wott_driver_gel.markers import find_markers
from wott_driver_gel.settings import open_gel
from wott_vision.render import marker_picture

from wott_hub.plugin_api import SettingsError
from wott_hub.td.builder import build_tactile_td


def dotted(background: np.ndarray, points: np.ndarray, mm_per_px: float) -> np.ndarray:
    """Black dots 0.4 mm across printed on the gel (80 % darker where they cover it)."""
    cover = marker_picture(points, 0.2 / mm_per_px, background.shape[:2], 1.0, intensity=1.0, background=0.0)
    cover = np.asarray(cover, np.float32)
    if cover.max() > 1.5:
        cover /= 255.0
    out = background.astype(np.float32) * (1 - 0.8 * cover[..., None])
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def grid(mini):
    pitch = 1.0 / mini.mm_per_px  # 1 mm
    ys, xs = np.mgrid[pitch / 2:480:pitch, pitch / 2:640:pitch]
    return np.column_stack([xs.ravel(), ys.ravel()])


def test_dark_and_bright_dots_are_found_and_a_plain_gel_shows_none(mini, grid):
    k = mini.mm_per_px
    found = find_markers(dotted(mini.background, grid, k), k)
    assert found is not None and found.polarity == "dark" and len(found.points) == len(grid)
    bright = 255 - dotted(255 - mini.background, grid, k)  # white dots on the (inverted) gel
    found = find_markers(bright, k)
    assert found is not None and found.polarity == "bright" and len(found.points) == len(grid)
    assert find_markers(mini.background, k) is None


def test_shear_of_the_dots_is_skin_displacement_on_the_nodes(mini, grid, tmp_path):
    k = mini.mm_per_px
    moved = grid.copy()
    box = (grid[:, 0] > 200) & (grid[:, 0] < 440) & (grid[:, 1] > 150) & (grid[:, 1] < 330)
    moved[box, 0] += 0.1 / k  # 0.1 mm along x under a finger that slides
    rest = dotted(mini.background, grid, k)
    pressed = dotted(mini.presses[5], grid, k)  # a real press on the marker gel (its dots left in place)
    write_recording(tmp_path / "f", rest, np.stack([dotted(mini.background, moved, k), pressed]), rest=5,
                    between=1)
    driver = open_gel("m", "gelsight-mini", {"source": str(tmp_path / "f"), "realtime": False},
                      max_frames=5)
    assert driver.description.shear
    td = build_tactile_td(driver.description)
    assert "skinDisplacement" in td["events"]

    async def go() -> list:
        out = [f async for f in driver.frames()]
        await driver.close()
        return out

    frames = asyncio.run(go())
    d = frames[1].displacement
    nodes = driver.description.mesh.nodes / k
    inside = (nodes[:, 0] > 260) & (nodes[:, 0] < 380) & (nodes[:, 1] > 200) & (nodes[:, 1] < 280)
    outside = (nodes[:, 0] < 120) | (nodes[:, 0] > 540)
    assert np.allclose(d[inside, 0], 0.1, atol=0.02) and np.abs(d[inside, 1]).max() < 0.02
    assert np.abs(d[outside, :2]).max() < 0.02
    assert frames[1].contacts == ()  # the dots moved: shear, not a contact
    assert np.abs(frames[2].displacement).max() < 0.02  # back at rest
    (press,) = frames[3].contacts  # a press on the marker gel is still one contact, near its label
    x, y = np.array(press.location[:2]) / k
    assert np.hypot(x - mini.centres_px[5][0], y - mini.centres_px[5][1]) < 20


def test_without_markers_no_skin_displacement_and_grid_refused(mini_recording):
    folder, _ = mini_recording
    driver = open_gel("m", "gelsight-mini", {"source": str(folder)})
    assert not driver.description.shear
    assert "skinDisplacement" not in build_tactile_td(driver.description)["events"]
    with pytest.raises(SettingsError, match='^markers: "grid", but the first frame'):
        open_gel("m", "gelsight-mini", {"source": str(folder), "markers": "grid"})
