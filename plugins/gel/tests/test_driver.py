"""Real GelSight Mini presses (Taxim's 24, hand-labelled) through the gel driver: every press found,
no contact on the background, centres and radii near the labels (generous bounds: the benchmark,
``wott-hub bench gel``, reports the numbers), and the health, tare and contact-unknown rules."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import pytest
from wott_driver_gel.driver import GelDriver
from wott_driver_gel.evaluation import write_recording
from wott_driver_gel.settings import open_gel

from wott_hub.plugin_api import DriverError, Health, TactileFrame

SHARED = Path(__file__).resolve().parents[3].parent / "shared" / "data"


def _run(driver: GelDriver) -> list[TactileFrame]:
    async def go() -> list[TactileFrame]:
        out = [f async for f in driver.frames()]
        await driver.close()
        return out

    return asyncio.run(go())


def test_every_real_press_is_one_contact_and_the_background_none(mini, mini_recording):
    folder, at = mini_recording
    n = 5 + 2 * len(at)
    driver = open_gel("mini", "gelsight-mini", {"source": str(folder), "realtime": False}, max_frames=n - 4)
    frames = _run(driver)
    assert len(frames) == n - 4
    by_frame = {k + 4: f for k, f in enumerate(frames)}  # frame 4 (the 5th at rest) is the first yielded
    pressed = [by_frame[k].contacts for k in at]
    rest = [f.contacts for k, f in by_frame.items() if k not in at]
    assert all(c is not None and len(c) == 1 for c in pressed), [len(c or ()) for c in pressed]
    assert all(c == () for c in rest)  # 0 phantoms on 25 background frames
    k = mini.mm_per_px
    centres = np.array([c[0].location[:2] for c in pressed if c]) / k
    err = np.hypot(*(centres - mini.centres_px).T) * k
    assert np.median(err) < 0.35  # mm; the labels scatter ~0.2 mm about each site
    radii = np.array([c[0].radius_mm for c in pressed if c]) / k
    ratio = radii / mini.radii_px
    assert 0.8 < np.median(ratio) < 1.2
    assert driver.health().state is Health.ok


def test_no_reference_while_the_image_changes_and_tare_says_why(mini, tmp_path):
    bg = mini.background
    frames = np.stack([bg, mini.presses[3], bg, mini.presses[10], bg, mini.presses[20]])
    write_recording(tmp_path / "f", frames[0], frames[1:], rest=1, between=0)
    driver = open_gel("mini", "gelsight-mini", {"source": str(tmp_path / "f"), "realtime": False,
                                                "rest_frames": 3}, max_frames=1)

    async def go() -> tuple[str, str]:
        it = driver.frames()
        task = asyncio.ensure_future(it.__anext__())
        loop = asyncio.get_running_loop()
        deadline = loop.time() + 60
        while not driver.health().reason.startswith("no rest frame yet: the image changed"):
            assert loop.time() < deadline, driver.health()
            await asyncio.sleep(0.01)
        reason = driver.health().reason
        with pytest.raises(DriverError) as e:
            driver.tare()
        task.cancel()
        await driver.close()
        return reason, str(e.value)

    reason, refused = asyncio.run(go())
    assert driver.health().state is Health.degraded
    assert "grey levels between frames" in reason
    assert refused.startswith("cannot tare: no rest reference yet (no rest frame yet")


def test_tare_refused_while_touched_and_taken_again_at_rest(mini, tmp_path):
    write_recording(tmp_path / "f", mini.background, mini.presses[:1], rest=3, between=4)
    driver = open_gel("mini", "gelsight-mini", {"source": str(tmp_path / "f"), "realtime": False,
                                                "rest_frames": 3}, max_frames=6)

    async def go() -> list[str]:
        said = []
        async for f in driver.frames():
            if f.contacts:
                with pytest.raises(DriverError, match="the gel is touched"):
                    driver.tare()
            elif driver.last_estimate is not None and not driver.estimator.retaking and not said:
                said.append(driver.tare())
        await driver.close()
        return said

    said = asyncio.run(go())
    assert said and "rest reference" in said[0]
    assert driver.estimator.has_reference and not driver.estimator.retaking  # taken again over 3 frames


def test_modelled_presses_on_the_real_digit_background(tmp_path):
    """The DIGIT path: its real rest frame (tacto's) with presses made by our own optical model
    (wott_driver_gel.model: no real DIGIT contact frames may be shipped)."""
    import cv2
    from wott_driver_gel.model import press_image

    bg = cv2.imread(str(SHARED / "digit" / "bg_digit_240_320.jpg"))
    assert bg is not None and bg.shape == (320, 240, 3)
    k = 0.0782
    truth = [(120.0, 160.0, 2.0, 0.5), (80.0, 90.0, 3.0, 0.8), (170.0, 250.0, 1.5, 0.3)]
    frames = np.stack([press_image(bg, x, y, r_mm=ball, depth_mm=d, mm_per_px=k, seed=i)
                       for i, (x, y, ball, d) in enumerate(truth)])
    rest = [press_image(bg, 0, 0, r_mm=1, depth_mm=0, mm_per_px=k, seed=10 + i) for i in range(5)]
    write_recording(tmp_path / "f", rest[0], frames)
    driver = open_gel("digit", "digit", {"source": str(tmp_path / "f"), "realtime": False},
                      max_frames=2 * len(truth) + 1)
    got = _run(driver)
    pressed = [f.contacts for f in got if f.contacts]
    assert len(pressed) == len(truth) and all(len(c) == 1 for c in pressed)
    for c, (x, y, ball, d) in zip(pressed, truth, strict=True):
        assert np.hypot(c[0].location[0] / k - x, c[0].location[1] / k - y) < 3.0  # px
        r = np.sqrt(2 * ball * d - d * d)
        assert c[0].radius_mm == pytest.approx(r, rel=0.3)
    assert driver.description.mesh.nodes[:, 0].max() == pytest.approx(240 * k, abs=1.0)
