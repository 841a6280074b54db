"""The driver through the plugin registry: frames from the simulator, and health on a real
failing source (an image sequence that is missing, then appears, then runs out)."""

import asyncio
import subprocess
import sys
import time

import numpy as np
import pytest
from wott_driver_flatpad.geometry import PadLayout
from wott_driver_flatpad.simulator import PadSimulator, RenderSettings

from wott_hub.drivers.base import Health
from wott_hub.plugins import DeviceConfig, Registry
from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameProcessor, ProcessingParams

SMALL = {"rows": 8, "cols": 8, "pitch_mm": 2.0, "marker_radius_mm": 0.4}


@pytest.fixture(scope="module")
def registry():
    return Registry(only=["flatpad"])


def open_device(registry, **settings):
    return registry.open_device(DeviceConfig("pad-test", "flat-vision", settings))


async def collect(driver, n, timeout=20.0):
    out = []

    async def run():
        async for f in driver.frames():
            out.append(f)
            if len(out) >= n:
                break

    await asyncio.wait_for(run(), timeout)
    await driver.close()
    return out


def test_family_is_listed_with_a_schema(registry):
    fam = registry.families()["flat-vision"]
    assert fam.plugin == "flatpad"
    for key in ("rows", "cols", "pitch_mm", "source", "scene", "depth_model", "optics"):
        assert key in fam.schema["properties"]
    assert [d.family for d in registry.demo_devices() if d.id == "flatpad-1"] == ["flat-vision"]


def test_bad_settings_name_the_setting(registry):
    from wott_hub.drivers.base import DriverError

    with pytest.raises(DriverError, match="rows"):
        open_device(registry, rows=20)
    with pytest.raises(DriverError, match="camera sees"):
        open_device(registry, pitch_mm=3.0)
    with pytest.raises(DriverError, match="depth_model"):
        open_device(registry, depth_model="/nonexistent/depth.json")


def test_simulated_pad_yields_frames_the_hub_can_process(registry):
    scene = Scene.from_dict({"step": [{"kind": "press", "at": [7.0, 7.0, 0.0], "start_s": 0.1,
                                       "duration_s": 0.4, "depth_mm": 1.5}]})
    drv = open_device(registry, **SMALL, realtime=False, fps=30.0, scene=_write_scene(scene))
    frames = asyncio.run(collect(drv, 20))
    assert drv.health().state is Health.ok
    assert all(f.displacement.shape == (64, 3) for f in frames)
    assert frames[1].t_ns - frames[0].t_ns == pytest.approx(1e9 / 30, abs=1e3)  # scene time, not wall time
    assert min(f.displacement[:, 2].min() for f in frames) < -1.0
    proc = FrameProcessor(drv.description.mesh, ProcessingParams(epsilon_mm=drv.description.epsilon_mm))
    actions = [a for f in frames for a in proc.process(f).actions]
    assert "touch" in actions or "press" in actions


def test_finite_scene_ends_the_device(registry):
    scene = Scene.from_dict({"step": [{"kind": "tap", "at": [7.0, 7.0, 0.0], "start_s": 0.0}]})
    drv = open_device(registry, **SMALL, realtime=False, fps=20.0, scene=_write_scene(scene))
    frames = asyncio.run(collect(drv, 1000))
    assert len(frames) == int(scene.duration_s * 20) + 1


def test_calibrated_depth_model_is_fitted_at_start(registry):
    drv = open_device(registry, **SMALL, realtime=False, depth_model="calibrate")
    assert drv.estimator.depth_model.source == "physical"  # nothing fitted before it runs
    asyncio.run(collect(drv, 2))
    m = drv.estimator.depth_model
    assert m.source.startswith("simulated presses") and m.samples > 100
    ideal = 1.41 * PadLayout(**SMALL).optics.z_eff_mm
    # the fitted gain stays near the optics' n·Z0; on this coarse grid it also makes up for the
    # finite-difference smoothing of the peak (a few per cent)
    assert m.coefficients[0] == pytest.approx(ideal, rel=0.15)


def _write_scene(scene: Scene) -> str:
    import tempfile

    lines = ['[scene]', f'name = "{scene.name}"', "loop = false"]
    for s in scene.steps:
        lines += ["[[step]]", f'kind = "{s.kind}"', f"at = {s.at.tolist()}", f"start_s = {s.start_s}",
                  f"duration_s = {s.duration_s}", f"depth_mm = {s.depth_mm}", f"radius_mm = {s.radius_mm}"]
    f = tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False)
    f.write("\n".join(lines) + "\n")
    f.close()
    return f.name


def test_source_failure_reports_disconnected_and_reconnects(registry, tmp_path):
    import cv2

    lay = PadLayout(**SMALL)
    scene = Scene.from_dict({"step": [{"kind": "press", "at": [7.0, 7.0, 0.0], "start_s": 0.0,
                                       "duration_s": 1.0, "depth_mm": 1.0}]})
    rest, _ = PadSimulator(lay, Scene("rest", ()), RenderSettings()).render(0.0)
    pressed, truth = PadSimulator(lay, scene, RenderSettings()).render(0.5)
    pattern = str(tmp_path / "frame_%03d.png")
    drv = open_device(registry, **SMALL, source=pattern, backoff_initial_s=0.02, backoff_cap_s=0.1)
    states: list[tuple[str, str]] = []

    async def run():
        frames = []
        agen = drv.frames()
        task = asyncio.ensure_future(agen.__anext__())
        # the files are not there yet: the driver must say so, and keep trying
        deadline = time.monotonic() + 5
        while drv.health().state is not Health.disconnected and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        states.append((drv.health().state, drv.health().reason))
        await asyncio.sleep(0.2)  # a few backoff rounds
        cv2.imwrite(pattern % 0, rest)
        cv2.imwrite(pattern % 1, pressed)
        frames.append(await asyncio.wait_for(task, 5))
        frames.append(await asyncio.wait_for(agen.__anext__(), 5))
        states.append((drv.health().state, drv.health().reason))
        # the sequence has ended: disconnected with that reason, then reopened from its start
        frames.append(await asyncio.wait_for(agen.__anext__(), 5))
        await agen.aclose()
        await drv.close()
        return frames

    frames = asyncio.run(run())
    assert states[0][0] is Health.disconnected and "frame_%03d.png" in states[0][1]
    assert states[1][0] is Health.ok
    assert drv.reconnects >= 1
    assert np.abs(frames[0].displacement).max() == 0.0  # the first frame is the rest reference
    err = frames[1].displacement - truth
    assert np.sqrt(np.mean(err[lay.mesh.free, 2] ** 2)) < 0.1
    assert np.abs(frames[2].displacement).max() < 0.1  # replayed from the start: the rest frame again


def test_registry_and_driver_do_not_import_cv2():
    code = (
        "import sys\n"
        "from wott_hub.plugins import DeviceConfig, Registry\n"
        "r = Registry(only=['flatpad'])\n"
        "d = r.open_device(DeviceConfig('p', 'flat-vision', {}))\n"
        "print(d.description.mesh.n_nodes)\n"
        "assert 'cv2' not in sys.modules, 'cv2 imported'\n"
        "assert 'onnxruntime' not in sys.modules, 'onnxruntime imported'\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "256"


def test_frames_at_rest_reuse_the_rest_picture_with_the_same_bytes():
    """Rest frames are exposed from a picture drawn once: byte for byte what drawing each frame gives."""
    from wott_vision.render import render_markers

    lay = PadLayout(**SMALL)
    scene = Scene.from_dict({"step": [{"kind": "press", "at": [7.0, 7.0, 0.0], "start_s": 0.0,
                                       "duration_s": 0.4, "depth_mm": 1.0}]})
    sim = PadSimulator(lay, scene, RenderSettings())
    reference_rng = np.random.default_rng(RenderSettings().seed)
    for t in (0.5, 0.6, 0.2, 0.7):  # rest, rest (reused), a press, rest again
        img, truth = sim.render(t)
        px, radius = sim.markers(t, truth)
        o = lay.optics
        expected = render_markers(px, radius, size=(o.height, o.width), blur_sigma=1.0, noise_std=2.0,
                                  rng=reference_rng)
        assert np.array_equal(img, expected)
    assert sim._rest is not None


def test_tare_and_recalibrate_without_a_reference_fail_saying_why():
    """Issue 44: they answered ``ok`` and did nothing while the pad had no rest reference."""
    from wott_driver_flatpad.settings import open_pad

    from wott_hub.drivers.base import DriverError

    driver = open_pad("pad", {"source": "sim"})  # not run: no frame, no reference
    for action in (driver.tare, driver.recalibrate):
        with pytest.raises(DriverError, match="no rest reference yet"):
            action()
