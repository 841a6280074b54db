"""Readings a user can trust (issue 14) on the barrel: markers unavailable at rest, the clamp,
no false pinch under a shearing slide."""

import asyncio

import numpy as np
import pytest
from wott_driver_barrel.settings import open_barrel
from wott_driver_barrel.simulator import BarrelSimulator
from wott_vision.render import render_markers
from wott_vision.simulated import SimulatedSource

from wott_hub.drivers.base import Health
from wott_hub.sim.scene import Scene
from wott_hub.tactile.processing import FrameProcessor, processing_params

PRESS = {"kind": "press", "at": [0.0, 53.0, 130.0], "start_s": 0.1, "duration_s": 0.4, "depth_mm": 5.0,
         "radius_mm": 14.0, "ramp_s": 0.1}


class PaintedOut:
    """Both cameras of the simulator, with the markers ``removed`` painted out of the skin."""

    def __init__(self, sim: BarrelSimulator, fps: float, removed=()) -> None:
        self.sim, self.fps, self.k = sim, fps, 0
        self.removed = np.asarray(removed, int)
        self.t_s, self.realtime, self.truth = 0.0, False, None
        self.rng = np.random.default_rng(0)

    def read(self):
        t = self.k / self.fps
        if t > self.sim.scene.duration_s:
            self.ended = True
            return False, None
        self.k += 1
        truth = self.sim.truth(t)
        points, radii = self.sim.layout.points_and_radii(truth)
        images = []
        for cam, p, r in zip(self.sim.layout.cameras, points, radii, strict=True):
            keep = np.ones(len(p), bool)
            keep[self.removed] = False
            images.append(render_markers(p[keep], r[keep], size=(cam.height, cam.width), blur_sigma=1.0,
                                         noise_std=2.0, rng=self.rng, intensity=235.0, background=22.0))
        self.t_s, self.truth = t, truth
        return True, tuple(images)

    def release(self) -> None:
        pass


def _run(driver, limit_s=180.0):
    async def go():
        out = []
        async for frame in driver.frames():
            out.append((frame, driver.last_truth, driver.health()))
        return out

    return asyncio.run(asyncio.wait_for(go(), limit_s))


@pytest.mark.parametrize("reference", ["first-frame", None])  # None: the default ("model")
@pytest.mark.parametrize("percent", [1, 5, 20])
def test_barrel_starts_with_markers_missing_and_reports_them(layout, percent, reference):
    m = layout.markers.n_markers
    n = max(1, round(percent / 100 * m))
    removed = np.sort(np.random.default_rng(percent).choice(m, n, replace=False))
    scene = Scene.from_dict({"step": [PRESS]})
    settings = {"realtime": False, "fps": 15.0}
    if reference is not None:
        settings["reference"] = reference
    driver = open_barrel("barrel-missing", settings)
    driver.open_source = lambda: PaintedOut(BarrelSimulator(layout, scene), 15.0, removed=removed)
    frames = _run(driver)
    assert len(frames) == int(scene.duration_s * 15) + 1
    health = frames[-1][2]
    assert health.state is Health.degraded
    assert health.reason.startswith(f"{2 * n} of {2 * m} markers unavailable")  # each seen by both cameras
    unknown = driver.unavailable_nodes
    mesh = driver.description.mesh
    # a node is unknown where its nearest marker is gone, and only there
    nearest = np.linalg.norm(mesh.nodes[:, None] - layout.markers.rest[None], axis=2).argmin(axis=1)
    assert unknown == np.flatnonzero(np.isin(nearest, removed) & mesh.free).tolist()
    eps = driver.description.epsilon_mm
    free = mesh.free
    known = free.copy()
    known[unknown] = False
    deep = [(f, t) for f, t, _ in frames if np.linalg.norm(t, axis=1).max() > 3.0]
    assert deep
    for f, t in deep:
        d = f.displacement
        if unknown:
            assert np.linalg.norm(d[unknown], axis=1).max() == 0.0  # unknown: never reported deformed
        e = np.linalg.norm(d[known] - t[known], axis=1)
        assert np.sqrt(np.mean(e**2)) < 0.4  # the rest of the skin keeps reading
        tn = np.linalg.norm(t, axis=1)
        assert np.linalg.norm(d, axis=1).max() > 0.5 * tn.max()
    for f, t, _ in frames:
        if np.abs(t).max() == 0.0:
            assert np.linalg.norm(f.displacement, axis=1).max() < eps


def test_model_output_beyond_the_bound_is_clamped(layout):
    # the default model is linear: marker motion ten times a real press's drives it far past the
    # skin's bound (through the images it saturates first: the tracker loses such jumps)
    from wott_driver_barrel.estimator import MAX_DISPLACEMENT_MM, clamp_norm

    driver = open_barrel("barrel-deep", {})
    truth = BarrelSimulator(layout, Scene.from_dict({"step": [PRESS]})).truth(0.3)
    d = driver.estimator.model.predict_markers(10 * layout.features(truth))
    over = np.linalg.norm(d, axis=1) > MAX_DISPLACEMENT_MM
    assert over.any()
    kept = d[~over].copy()
    assert clamp_norm(d, MAX_DISPLACEMENT_MM) == int(over.sum())
    np.testing.assert_allclose(np.linalg.norm(d[over], axis=1), MAX_DISPLACEMENT_MM)
    np.testing.assert_array_equal(d[~over], kept)  # plausible nodes untouched


def test_slide_under_shear_is_no_pinch_on_the_barrel(layout):
    scene = Scene.from_dict({"step": [{"kind": "slide", "at": [0.0, 53.0, 100.0], "to": [0.0, 53.0, 160.0],
                                       "start_s": 0.2, "duration_s": 1.2, "depth_mm": 4.0, "shear_mm": 1.5,
                                       "radius_mm": 12.0}]})
    driver = open_barrel("barrel-slide", {"realtime": False, "fps": 15.0})
    driver.open_source = lambda: SimulatedSource(BarrelSimulator(layout, scene), 15.0, realtime=False)
    frames = _run(driver)
    proc = FrameProcessor(driver.description.mesh, processing_params(driver.description))
    actions = [a for f, _, _ in frames for a in proc.process(f).actions]
    assert "pinch" not in actions
    assert actions[0] in ("touch", "collision") and "slip" in actions and actions[-1] == "release"
