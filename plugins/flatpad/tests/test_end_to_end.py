"""Scene in, marker images out, displacement field back: against the scene's ground truth.

Tolerances (docs/flat-pad.md, "accuracy"): over the free markers of every frame,
in-plane RMSE <= 0.02 mm everywhere but slides, depth RMSE <= 0.06 mm for presses,
taps and pinches. Under a shearing slide the gel's in-plane stretch is read as
depth (the no-stretch prior of the depth model): depth RMSE <= 0.8 mm there.
"""

import numpy as np
import pytest
from wott_driver_flatpad.estimator import PadEstimator
from wott_driver_flatpad.evaluation import play_scene
from wott_driver_flatpad.geometry import PadLayout
from wott_driver_flatpad.settings import demo_scene_path
from wott_driver_flatpad.simulator import PadSimulator, RenderSettings
from wott_vision.simulated import SimulatedSource

from wott_hub.sim.scene import Scene


@pytest.fixture(scope="module")
def demo_score():
    # 20 frames/s keeps the test fast; the tracker still follows the slide (< half a pitch per frame)
    return play_scene(PadLayout(), Scene.load(demo_scene_path()), fps=20.0)


def test_demo_scene_shear_within_tolerance(demo_score):
    s = demo_score
    assert s.frames > 100 and s.lost == 0
    for kind in ("rest", "press"):
        assert s.shear_rmse(kind) <= 0.02, kind
    assert s.shear_rmse("slide") <= 0.2


def test_demo_scene_depth_within_tolerance(demo_score):
    s = demo_score
    assert s.depth_rmse("rest") <= 0.04
    assert s.depth_rmse("press") <= 0.06
    assert s.max_depth_err["press"] <= 0.3
    assert s.depth_rmse("slide") <= 0.8


def test_small_grid_press_and_pinch():
    lay = PadLayout(7, 9, pitch_mm=2.5, marker_radius_mm=0.5)
    scene = Scene.from_dict({"step": [
        {"kind": "press", "at": [10.0, 7.5, 0.0], "start_s": 0.1, "duration_s": 0.5, "depth_mm": 1.5,
         "radius_mm": 6.0},
        {"kind": "pinch", "at": [5.0, 7.5, 0.0], "to": [15.0, 7.5, 0.0], "approach_mm": 4.0,
         "start_s": 0.8, "duration_s": 0.5, "depth_mm": 1.0, "radius_mm": 5.0},
    ]})
    s = play_scene(lay, scene, fps=20.0)
    assert s.lost == 0
    assert s.shear_rmse("press") <= 0.02
    assert s.depth_rmse("press") <= 0.1


def test_simulated_camera_is_a_video_capture():
    lay = PadLayout(8, 8, pitch_mm=2.0, marker_radius_mm=0.4)
    scene = Scene.from_dict({"step": [{"kind": "tap", "at": [7.0, 7.0, 0.0], "start_s": 0.05}]})
    cam = SimulatedSource(PadSimulator(lay, scene, RenderSettings(noise_std=0.0)), fps=50.0, realtime=False)
    assert cam.isOpened()
    frames = []
    while True:
        ok, img = cam.read()
        if not ok:
            break
        frames.append((cam.t_s, img, cam.truth))
    assert cam.ended and len(frames) == int(scene.duration_s * 50) + 1
    t, img, truth = frames[5]  # 0.1 s: mid-tap
    assert img.shape == (480, 640) and img.dtype == np.uint8
    assert truth[:, 2].min() < -1.0
    est = PadEstimator(lay)
    est.set_reference(frames[0][1])
    d = est.update(img).displacement
    # a 2 mm pitch under a 5 mm tip: the grid-scale gradient costs ~10 % of the peak
    assert d[:, 2].min() == pytest.approx(truth[:, 2].min(), rel=0.15)


def test_pressed_markers_are_drawn_bigger_and_pushed_outwards():
    lay = PadLayout()
    scene = Scene.from_dict({"step": [{"kind": "press", "at": [16.5, 11.25, 0.0], "depth_mm": 2.0,
                                       "start_s": 0.0, "duration_s": 1.0}]})
    sim = PadSimulator(lay, scene)
    px0, r0 = sim.markers(-1.0)
    px, r = sim.markers(0.5)
    i = 7 * 16 + 11  # the node under the press, right of the optical axis
    assert r[i] > 1.05 * r0[i]
    assert px[i, 0] > px0[i, 0] + 0.5  # magnification about the principal point


def test_a_blank_frame_loses_every_marker_but_stays_finite():
    lay = PadLayout(8, 8, pitch_mm=2.0, marker_radius_mm=0.4)
    est = PadEstimator(lay)
    est.set_reference(PadSimulator(lay, Scene("rest", ())).render(0.0)[0])
    e = est.update(np.zeros((480, 640), np.uint8))  # lens covered, or the LED died
    assert e.lost == lay.n_markers
    assert np.isfinite(e.displacement).all() and np.abs(e.displacement).max() == 0.0
