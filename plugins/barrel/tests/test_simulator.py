import numpy as np
from scipy.spatial import cKDTree
from wott_driver_barrel.simulator import BarrelSimulator, RenderSettings
from wott_vision.markers import detect_markers
from wott_vision.simulated import SimulatedSource

from wott_hub.sim.scene import Scene

PRESS = {"scene": {"name": "press", "loop": False},
         "step": [{"kind": "press", "at": [0.0, 53.0, 130.0], "start_s": 0.0, "duration_s": 0.4,
                   "depth_mm": 5.0, "radius_mm": 15.0, "ramp_s": 0.1}]}


def test_rest_frames_show_all_markers_where_the_camera_model_puts_them(layout):
    sim = BarrelSimulator(layout, Scene.from_dict(PRESS))
    images = sim.render_displacement(None)
    for img, ref in zip(images, layout.reference_px, strict=True):
        assert img.shape == (480, 640) and img.dtype == np.uint8
        assert 15 < np.median(img) < 30  # dark skin, like the real frames
        found = detect_markers(img)
        assert len(found) == 256
        dist, _ = cKDTree(found).query(ref)
        assert np.sqrt(np.mean(dist**2)) < 0.06  # px


def test_a_press_moves_the_pressed_markers_towards_the_centre(layout):
    sim = BarrelSimulator(layout, Scene.from_dict(PRESS), RenderSettings(noise_std=0.0))
    (bottom, _), truth = sim.render(0.2)
    assert truth[layout.mesh.free].any() and not truth[~layout.mesh.free].any()
    moved = layout.image_points(truth)[0]
    ref = layout.reference_px[0]
    r_ref = np.hypot(*(ref - [319.5, 239.5]).T)
    r_now = np.hypot(*(moved - [319.5, 239.5]).T)
    pressed = np.argmax(r_ref - r_now)
    assert pressed % 16 == 4  # the ray at +y (azimuth 90 degrees)
    # every marker that moved and stays clear of its neighbours is detected where it went
    found = detect_markers(bottom)
    gap = cKDTree(moved).query(moved, k=2)[0][:, 1]
    radius = layout.points_and_radii(truth)[1][0]
    clear = (np.hypot(*(moved - ref).T) > 0.5) & (gap > 2 * radius + 2)
    assert clear.sum() >= 1
    assert cKDTree(found).query(moved[clear])[0].max() < 0.1


def test_simulated_cameras_end_with_a_non_looping_scene(layout):
    cams = SimulatedSource(BarrelSimulator(layout, Scene.from_dict(PRESS)), fps=20, realtime=False)
    n = 0
    while True:
        ok, frames = cams.read()
        if not ok:
            break
        assert len(frames) == 2 and cams.truth is not None
        n += 1
    assert cams.ended and "ended" in cams.failure
    assert n == int(Scene.from_dict(PRESS).duration_s * 20) + 1


def test_frames_at_rest_reuse_the_rest_pictures_with_the_same_bytes(layout):
    """Rest frames are exposed from pictures drawn once: byte for byte what drawing each frame gives."""
    from wott_vision.render import render_markers

    sim = BarrelSimulator(layout, Scene.from_dict(PRESS))  # touching in [0, 0.4) s
    reference_rng = np.random.default_rng(RenderSettings().seed)
    s = sim.settings
    for t in (0.5, 0.6, 0.2, 0.7):  # rest, rest (reused), a press, rest again
        images, truth = sim.render(t)
        points, radii = layout.points_and_radii(truth)
        for img, cam, p, r in zip(images, layout.cameras, points, radii, strict=True):
            expected = render_markers(p, r, size=(cam.height, cam.width), blur_sigma=s.blur_sigma,
                                      noise_std=s.noise_std, rng=reference_rng, intensity=s.intensity,
                                      background=s.background)
            assert np.array_equal(img, expected)
    assert sim._rest is not None
