"""The barrel driver end to end: simulator scene in, frames out, accuracy against ground truth; health."""

import asyncio
import subprocess
import sys
import time

import numpy as np
import pytest
from wott_driver_barrel.estimator import order_like
from wott_driver_barrel.settings import demo_scene_path, open_barrel
from wott_driver_barrel.simulator import BarrelSimulator
from wott_driver_barrel.training import rmse_mm

from wott_hub.drivers.base import DriverError, Health
from wott_hub.sim.scene import Scene

# Stated tolerance (docs/barrel-vision.md): on the demo scene at 30 fps through the whole chain
# (render both cameras, detect, track, ONNX model), measured 0.064 mm / 0.64 mm (docs/benchmarks.md).
TOL_RMSE_FREE_MM = 0.08  # over all free nodes and frames
TOL_RMSE_DEFORMED_MM = 0.8  # over nodes displaced more than 0.5 mm


def _run(driver, limit_s=60.0):
    async def go():
        out = []
        async for frame in driver.frames():
            out.append((frame, driver.last_truth))
        return out

    return asyncio.run(asyncio.wait_for(go(), limit_s))


def test_demo_scene_end_to_end_matches_ground_truth():
    scene = Scene.load(demo_scene_path())
    n = int(scene.duration_s * 30)
    driver = open_barrel("barrel-t", {"realtime": False, "fps": 30.0}, max_frames=n)
    frames = _run(driver)
    assert len(frames) == n
    free = driver.description.mesh.free
    est = np.array([f.displacement[free].ravel() for f, _ in frames])
    truth = np.array([t[free].ravel() for _, t in frames])
    assert rmse_mm(est, truth) < TOL_RMSE_FREE_MM
    assert rmse_mm(est, truth, min_norm_mm=0.5) < TOL_RMSE_DEFORMED_MM
    assert rmse_mm(est, truth) < 0.5 * rmse_mm(np.zeros_like(truth), truth)
    # where a contact is, the estimate finds it: its most displaced node is near a truly pressed one
    nodes = driver.description.mesh.nodes[free]
    e3, t3 = est.reshape(n, -1, 3), truth.reshape(n, -1, 3)
    for e, t in zip(e3, t3, strict=True):
        tn = np.linalg.norm(t, axis=1)
        if tn.max() > 3.0:
            en = np.linalg.norm(e, axis=1)
            pressed = nodes[tn > 0.5 * tn.max()]
            assert np.linalg.norm(pressed - nodes[np.argmax(en)], axis=1).min() < 25.0
        if tn.max() == 0.0:  # at rest: no phantom touch above the hub's epsilon
            assert np.linalg.norm(e, axis=1).max() < driver.description.epsilon_mm
    assert driver.health().state is Health.ok


PRESS_TOML = """
[scene]
name = "press"
loop = false

[[step]]
kind = "press"
at = [0.0, 53.0, 130.0]
start_s = 0.3
duration_s = 0.6
depth_mm = 5.0
radius_mm = 16.0
ramp_s = 0.2
"""


def test_first_frame_reference_orders_detected_markers_like_the_model(tmp_path, layout):
    from wott_vision.markers import detect_markers

    sim = BarrelSimulator(layout, Scene.load(demo_scene_path()))
    images = sim.render_displacement(None)
    for img, ref in zip(images, layout.reference_px, strict=True):
        pts = detect_markers(img)
        shuffled = pts[np.random.default_rng(0).permutation(len(pts))]
        ordered = order_like(shuffled, ref, 16)
        assert np.abs(ordered - ref).max() < 0.3
    # a driver that learns its reference from the first frame recovers a press as well
    scene = tmp_path / "press.toml"
    scene.write_text(PRESS_TOML)
    driver = open_barrel("ff", {"scene": str(scene), "reference": "first-frame", "realtime": False})
    frames = _run(driver)
    free = driver.description.mesh.free
    est = np.array([f.displacement[free].ravel() for f, _ in frames])
    truth = np.array([t[free].ravel() for _, t in frames])
    assert rmse_mm(est, truth) < 0.5 * rmse_mm(np.zeros_like(truth), truth)
    with pytest.raises(Exception, match="markers detected, expected 256"):
        order_like(pts[:200], layout.reference_px[0], 16)


def _write_videos(tmp_path, layout, displacements):
    import cv2

    sim = BarrelSimulator(layout, Scene.load(demo_scene_path()))
    paths = [tmp_path / "bottom.avi", tmp_path / "top.avi"]
    writers = [cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480), False)
               for p in paths]
    for d in displacements:
        for w, img in zip(writers, sim.render_displacement(d), strict=True):
            w.write(img)
    for w in writers:
        w.release()
    return [str(p) for p in paths]


def test_recorded_cameras_that_end_disconnect_with_the_reason_and_reconnect(tmp_path, layout):
    paths = _write_videos(tmp_path, layout, [None] * 4)
    driver = open_barrel("rec", {"source": paths, "backoff_initial_s": 0.02, "backoff_cap_s": 0.1},
                         max_frames=10)
    seen = []

    async def go():
        async for frame in driver.frames():
            seen.append((frame.displacement.copy(), driver.health(), driver.reconnects))

    asyncio.run(asyncio.wait_for(go(), 30))
    assert len(seen) == 10
    assert driver.reconnects == 2  # 4 + 4 + 2 frames: the files ended twice and were reopened
    assert [s[2] for s in seen] == [0] * 4 + [1] * 4 + [2] * 2
    for d, health, _ in seen:
        assert health.state is Health.ok  # frames flow again after each reconnect
        assert np.linalg.norm(d, axis=1).max() < 0.1  # a recording of the skin at rest reads as rest


def test_missing_cameras_report_disconnected_and_retry_with_growing_backoff(tmp_path, layout):
    bottom, top = str(tmp_path / "bottom.avi"), str(tmp_path / "top.avi")
    driver = open_barrel("cam", {"source": [bottom, top], "backoff_initial_s": 0.02, "backoff_cap_s": 0.16},
                         max_frames=2)
    states = []

    async def go():
        async def consume():
            return [f async for f in driver.frames()]

        task = asyncio.create_task(consume())
        t0 = time.monotonic()
        while driver.backoff.attempts < 4:
            await asyncio.sleep(0.01)
            assert time.monotonic() - t0 < 10
        states.append(driver.health())
        # the cameras appear (plugged in): the driver picks them up on its next attempt
        await asyncio.to_thread(_write_videos, tmp_path, layout, [None] * 3)
        return await asyncio.wait_for(task, 10)

    frames = asyncio.run(go())
    health = states[0]
    assert health.state is Health.disconnected
    assert "bottom camera" in health.reason and "no such file" in health.reason
    assert [driver.backoff.base_delay(k) for k in range(4)] == [0.02, 0.04, 0.08, 0.16]
    assert len(frames) == 2 and driver.health().state is Health.ok
    assert driver.backoff.attempts == 0  # reset by the first good frame


def test_an_image_model_drives_the_simulator_without_tracking(tmp_path):
    from onnx import TensorProto, helper, numpy_helper, save_model

    # two 128x128 frames -> their mean brightness -> a uniform displacement of the 585 free nodes
    graph = helper.make_graph(
        [helper.make_node("ReduceMean", ["frames"], ["m"], keepdims=0),
         helper.make_node("Reshape", ["m", "shape"], ["m2"]),
         helper.make_node("MatMul", ["m2", "w"], ["d"])],
        "mean_image", [helper.make_tensor_value_info("frames", TensorProto.FLOAT, [1, 2, 128, 128])],
        [helper.make_tensor_value_info("d", TensorProto.FLOAT, [1, 1755])],
        [numpy_helper.from_array(np.array([1, 1], np.int64), "shape"),
         numpy_helper.from_array(np.full((1, 1755), 0.5, np.float32), "w")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    save_model(model, str(tmp_path / "img.onnx"))
    driver = open_barrel("img", {"model": str(tmp_path / "img.onnx"), "realtime": False}, max_frames=3)
    frames = _run(driver)
    assert len(frames) == 3
    assert driver.last_estimate.tracked_px == () and not driver.estimator.uses_markers
    d = frames[0][0].displacement
    free = driver.description.mesh.free
    assert np.allclose(d[~free], 0.0) and np.ptp(d[free]) < 1e-6
    assert 0.0 < d[free][0, 0] < 0.5  # half the mean grey level of a dark skin with white dots


def test_plugin_registration_imports_neither_cv2_nor_onnxruntime():
    code = (
        "import sys\n"
        "import wott_driver_barrel.dataset, wott_driver_barrel.driver, wott_driver_barrel.estimator\n"
        "import wott_driver_barrel.model, wott_driver_barrel.onnx_export, wott_driver_barrel.simulator\n"
        "import wott_driver_barrel.training\n"
        "from wott_hub.plugins import Registry\n"
        "r = Registry(only=['barrel'])\n"
        "assert 'barrel-vision' in r.families(), r.plugins()\n"
        "assert r.demo_devices()\n"
        "bad = [m for m in ('cv2', 'onnxruntime') if m in sys.modules]\n"
        "print(bad)\n"
        "sys.exit(1 if bad else 0)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr


def test_registry_opens_the_demo_device():
    from wott_hub.plugins import Registry

    registry = Registry(only=["barrel"])
    cfg = next(c for c in registry.demo_devices() if c.family == "barrel-vision")
    driver = registry.open_device(cfg)
    assert driver.description.mesh.n_nodes == 707 and driver.description.family == "barrel-vision"
    with pytest.raises(Exception, match="fps"):
        registry.open_device(type(cfg)(cfg.id, cfg.family, {"fps": -1}))


def test_a_missing_camera_device_is_reported_and_retried():
    driver = open_barrel("dev", {"source": [63, 62], "backoff_initial_s": 0.01, "backoff_cap_s": 0.02})

    async def go():
        async def consume():
            return [f async for f in driver.frames()]

        task = asyncio.create_task(consume())
        while driver.backoff.attempts < 3:
            await asyncio.sleep(0.01)
        health = driver.health()
        await driver.close()
        assert await asyncio.wait_for(task, 5) == []
        return health

    health = asyncio.run(asyncio.wait_for(go(), 20))
    assert health.state is Health.disconnected
    assert health.reason.startswith("bottom camera: cannot open camera device 63")


@pytest.mark.parametrize(("settings", "message"), [
    ({"detector": {"min_area": 50, "max_area": 10}}, "detector: need 0 < min_area <= max_area"),
    ({"tracker": {"max_gate_px": 0.5}}, "tracker.max_gate_px"),
])
def test_bad_detector_and_tracker_settings_are_refused_when_the_device_opens(settings, message):
    # the detectors and trackers themselves are built at the first frame (BarrelEstimator.prepare)
    with pytest.raises(DriverError, match=message):
        open_barrel("b1", settings)
