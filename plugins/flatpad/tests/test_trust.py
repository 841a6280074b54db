"""Readings a user can trust (issue 14) on the flat pad: markers unavailable at rest (in the health
and in the ``unavailableNodes`` property a real hub serves), clamps, no false pinch under a shearing
slide, a press below epsilon explained in the health."""

import asyncio
import json
import threading
import time

import httpx
import numpy as np
import pytest
from wott_driver_flatpad.estimator import PadEstimator
from wott_driver_flatpad.geometry import PadLayout
from wott_driver_flatpad.settings import open_pad
from wott_driver_flatpad.simulator import PadSimulator
from wott_vision.render import render_markers
from wott_vision.simulated import SimulatedSource

from wott_hub.config import HubConfig
from wott_hub.drivers.base import Health
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY
from wott_hub.sim.scene import Scene
from wott_hub.tactile.processing import FrameProcessor, processing_params
from wott_hub.td.validate import validate_td

PRESS = {"kind": "press", "at": [16.5, 11.25, 0.0], "start_s": 0.1, "duration_s": 0.5, "depth_mm": 1.0,
         "radius_mm": 5.0}


class PaintedOut:
    """The simulator read like a camera, with some markers painted out (``removed``) in every image,
    or drawn merged with their right-hand neighbour (``merged``): one blob between the two."""

    def __init__(self, sim: PadSimulator, fps: float, removed=(), merged=()) -> None:
        self.sim, self.fps, self.k = sim, fps, 0
        self.removed, self.merged = np.asarray(removed, int), np.asarray(merged, int)
        self.t_s, self.realtime, self.truth = 0.0, False, None
        self.rng = np.random.default_rng(0)

    def read(self):
        t = self.k / self.fps
        if t > self.sim.scene.duration_s:
            self.ended = True
            return False, None
        self.k += 1
        truth = self.sim.truth(t)
        px, radius = self.sim.markers(t, truth)
        keep = np.ones(len(px), bool)
        keep[self.removed] = False
        px, radius = px.copy(), radius.copy()
        for m in self.merged:  # marker m and m + 1 drawn as one bigger dot half-way
            px[m] = (px[m] + px[m + 1]) / 2
            radius[m] *= 1.6
            keep[m + 1] = False
        o = self.sim.layout.optics
        img = render_markers(px[keep], radius[keep], size=(o.height, o.width), blur_sigma=1.0, noise_std=2.0,
                             rng=self.rng)
        self.t_s, self.truth = t, truth
        return True, img

    def release(self) -> None:
        pass


def _run(driver, limit_s=120.0):
    async def go():
        out = []
        async for frame in driver.frames():
            out.append((frame, driver.last_truth, driver.health()))
        return out

    return asyncio.run(asyncio.wait_for(go(), limit_s))


@pytest.mark.parametrize("percent", [1, 5, 20])
def test_pad_starts_with_markers_missing_and_reports_them(percent):
    lay = PadLayout()
    free = np.flatnonzero(lay.mesh.free)
    n = max(1, round(percent / 100 * lay.n_markers))
    removed = np.sort(np.random.default_rng(percent).choice(free, n, replace=False))
    scene = Scene.from_dict({"step": [PRESS]})
    driver = open_pad("pad-missing", {"source": "sim", "fps": 20.0, "realtime": False})
    driver.open_source = lambda: PaintedOut(PadSimulator(lay, scene), 20.0, removed=removed)
    frames = _run(driver)
    assert len(frames) == int(scene.duration_s * 20) + 1  # the rest frame yields zeros, then every frame
    assert driver.unavailable_nodes == removed.tolist()
    health = frames[-1][2]
    assert health.state is Health.degraded
    assert health.reason.startswith(f"{n} of 256 markers unavailable")
    assert str(removed[0]) in health.reason
    eps = driver.description.epsilon_mm
    deep = [(f, t) for f, t, _ in frames if np.abs(t[:, 2]).max() > 0.9]
    assert deep  # the press was seen
    keep = np.setdiff1d(free, removed)
    for f, t in deep:
        d = f.displacement
        assert np.linalg.norm(d[removed], axis=1).max() == 0.0  # unknown: never reported deformed
        assert np.linalg.norm(d, axis=1).max() > 5 * eps  # and the rest of the pad keeps reading
        err = d[keep, 2] - t[keep, 2]
        assert np.sqrt(np.mean(err**2)) < 0.15
    for f, t, _ in frames:
        if np.abs(t).max() == 0.0:  # at rest: no phantom deformation next to the holes
            assert np.linalg.norm(f.displacement, axis=1).max() < eps


def test_merged_and_missing_markers_leave_a_usable_reference():
    lay = PadLayout()
    sim = PadSimulator(lay, Scene.from_dict({"step": [PRESS]}))
    reader = PaintedOut(sim, 20.0, removed=[40, 41, 90], merged=[120, 200])
    est = PadEstimator(lay)
    est.set_reference(reader.read()[1])
    assert est.unavailable_nodes == [40, 41, 90, 120, 121, 200, 201]
    for _ in range(6):  # 0.25 s: mid-press
        _, img = reader.read()
    e = est.update(img)
    assert e.unavailable == 7 and e.lost == 0
    assert e.displacement[est.unavailable_nodes].max() == 0.0
    assert e.displacement[:, 2].min() == pytest.approx(reader.truth[:, 2].min(), abs=0.2)


def test_a_press_through_the_gel_is_clamped_to_its_thickness_and_flagged():
    # 40 mm on a 4 mm pad (issue 14: read as 34 mm)
    scene = Scene.from_dict({"step": [dict(PRESS, depth_mm=40.0, radius_mm=8.0)]})
    lay = PadLayout()
    driver = open_pad("pad-deep", {"source": "sim", "fps": 20.0, "realtime": False})
    driver.open_source = lambda: SimulatedSource(PadSimulator(lay, scene), 20.0, realtime=False)
    frames = _run(driver)
    assert max(np.abs(f.displacement[:, 2]).max() for f, _, _ in frames) <= 4.0
    flagged = [h for _, _, h in frames if "beyond the physical bound" in h.reason]
    assert flagged and all(h.state is Health.degraded for h in flagged)
    assert driver.clamped_frames == len(flagged)


def _actions(frames, description):
    proc = FrameProcessor(description.mesh, processing_params(description))
    out = []
    for f, _, _ in frames:
        out += proc.process(f).actions
    return out


def test_slide_under_shear_is_no_pinch_on_the_pad():
    # issue 14: a slide with 0.3 mm shear on the 16x16 pad gave touch, slip, pinch
    scene = Scene.from_dict({"step": [{"kind": "slide", "at": [8.0, 11.25, 0.0], "to": [15.0, 11.25, 0.0],
                                       "start_s": 0.2, "duration_s": 1.0, "depth_mm": 1.0, "shear_mm": 0.3,
                                       "radius_mm": 5.0}]})
    lay = PadLayout()
    driver = open_pad("pad-slide", {"source": "sim", "fps": 30.0, "realtime": False})
    driver.open_source = lambda: SimulatedSource(PadSimulator(lay, scene), 30.0, realtime=False)
    actions = _actions(_run(driver), driver.description)
    assert "pinch" not in actions
    assert actions[0] == "touch" and actions[-1] == "release" and "slip" in actions


def test_a_press_below_epsilon_for_long_is_reported_in_the_health():
    driver = open_pad("pad-light", {"source": "sim", "below_threshold_s": 0.5})
    eps = driver.description.epsilon_mm
    n = driver.description.mesh.n_nodes
    light = np.zeros((n, 3))
    light[100, 2] = -0.9 * eps  # above the noise floor, under epsilon
    common = dict(lost=0, total=n, what="markers", unavailable=[], n_markers=n, clamped=0)
    for k in range(20):  # 0.05 s apart: 0.95 s in all
        driver._report_health(light, k * 50_000_000, **common)
        if k * 0.05 < 0.5:
            assert driver.health().reason == ""
    h = driver.health()
    assert h.state is Health.ok and h.reason.startswith("below threshold")
    driver._report_health(np.zeros((n, 3)), 10**9, **common)  # back at rest: explained no more
    assert driver.health().reason == ""


class _Hub:
    """A real hub on 127.0.0.1 (free ports) in its own thread and event loop."""

    def __init__(self, config: HubConfig) -> None:
        from wott_hub.hub import Hub

        self.hub = Hub(config)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.started = threading.Event()

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_until_complete(self.hub.start())
        self.started.set()
        self.loop.run_forever()

    def __enter__(self) -> "_Hub":
        self.thread.start()
        assert self.started.wait(60), "the hub did not start"
        return self

    def call(self, coro):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(60)

    def __exit__(self, *exc) -> None:
        self.call(self.hub.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


def test_painted_out_markers_are_listed_in_the_unavailable_nodes_property(tmp_path):
    lay = PadLayout()
    free = np.flatnonzero(lay.mesh.free)
    n = round(0.05 * lay.n_markers)  # 5 %
    removed = np.sort(np.random.default_rng(5).choice(free, n, replace=False)).tolist()
    scene = Scene.from_dict({"step": [PRESS]})
    driver = open_pad("pad-holes", {"source": "sim", "fps": 20.0, "realtime": False})
    driver.open_source = lambda: PaintedOut(PadSimulator(lay, scene), 20.0, removed=removed)
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), devices=())
    with _Hub(cfg) as h:
        h.call(h.hub._fleet.add_driver(driver, family="flatpad"))
        td = httpx.get(h.hub.td_url("pad-holes"), timeout=10).json()
        assert validate_td(td) == []
        aff = td["properties"]["unavailableNodes"]
        assert aff["observable"] is True and aff["@type"] == "tac:UnavailableNodes"
        href = aff["forms"][0]["href"]
        value = None
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            value = httpx.get(href, timeout=10).json()
            if value["numOfUnavailableNodes"]:
                break
            time.sleep(0.2)
        assert value == {"numOfUnavailableNodes": n, "arrayOfUnavailableNodes": removed}
        # published as a property change, once (the list does not change frame to frame)
        while h.hub._fleet.running["pad-holes"].pipeline.state != "ended" and time.monotonic() < deadline:
            time.sleep(0.2)
        assert h.hub._history.writer.flush()
        reader = h.hub._history.reader
        recs, _ = reader.rows("pad-holes", 0, 1 << 62, (KIND_PROPERTY, "unavailableNodes"), limit=100)
        assert len(recs) == 1 and json.loads(recs[0].data) == value
        # and never reported deformed: the press was, the skin packets name none of the unknown nodes
        packets, _ = reader.rows("pad-holes", 0, 1 << 62, (KIND_EVENT, "skinDeformedDetection"), limit=10_000)
        named = {p["deformedNodeID"] for r in packets for p in json.loads(r.data)["arrayOfDeformedNodes"]}
        assert packets and named and not named & set(removed)
