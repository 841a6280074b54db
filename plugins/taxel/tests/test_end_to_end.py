"""Scene in, bytes on a real pty, frames out: the recovered displacement matches the ground truth.

Stated tolerance: every node of every frame within half a count of the taxel's
16-bit value (``Compliance.quantum_mm / 2``, 1.3e-4 mm for 3 mm of Ecoflex
00-30 at 0.01 kPa per count) of the ground truth, for scenes without shear
(a pressure taxel cannot sense shear; with shear, the normal component matches).
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from wott_driver_taxel.compliance import Compliance
from wott_driver_taxel.driver import TaxelDriver
from wott_driver_taxel.plugin import open_taxel_device
from wott_driver_taxel.simulator import TaxelSimulator

from wott_hub.drivers.base import DriverError, Health
from wott_hub.plugins import DeviceConfig, Registry
from wott_hub.sim.scene import Scene
from wott_hub.tactile import flat_pad

# Every gesture within 1.1 s, so a test plays the whole scene at 200 frames/s in about a second.
SCENE = """
[scene]
name = "e2e"
loop = true
[[step]]
kind = "press"
at = [20.0, 14.0, 0.0]
start_s = 0.05
duration_s = 0.3
depth_mm = 2.0
radius_mm = 10.0
[[step]]
kind = "slide"
at = [6.0, 6.0, 0.0]
to = [30.0, 22.0, 0.0]
start_s = 0.4
duration_s = 0.3
depth_mm = 1.0
radius_mm = 8.0
[[step]]
kind = "tap"
at = [30.0, 6.0, 0.0]
start_s = 0.75
depth_mm = 1.5
radius_mm = 6.0
[[step]]
kind = "pinch"
at = [4.0, 14.0, 0.0]
to = [36.0, 14.0, 0.0]
approach_mm = 12.0
start_s = 0.8
duration_s = 0.3
depth_mm = 1.2
radius_mm = 6.0
"""
RATE = 200.0


@pytest.fixture(scope="module")
def registry() -> Registry:
    return Registry(only=["taxel"])


async def play(driver, n_frames: int, pairs: list | None = None):
    """(frame, ground truth) pairs for the first n frames, checked against the simulator's record
    (appended to ``pairs`` as they come, if given)."""
    pairs = [] if pairs is None else pairs
    async for f in driver.frames():
        truth = driver.simulator.truth(driver.last_seq)
        assert truth is not None
        pairs.append((f, truth))
        if len(pairs) == n_frames:
            break
    await driver.close()
    return pairs


@pytest.mark.parametrize("protocol", ["binary", "ascii"])
def test_scene_to_frames_matches_the_ground_truth(registry, tmp_path, protocol):
    scene_file = tmp_path / "e2e.toml"
    scene_file.write_text(SCENE)
    cfg = DeviceConfig("t1", "taxel-array", {"simulate": True, "scene": str(scene_file), "rate_hz": RATE,
                                              "rows": 8, "cols": 10, "protocol": protocol})
    driver = registry.open_device(cfg)
    assert driver.description.mesh.n_nodes == 80 and driver.description.family == "taxel-array"
    pairs = asyncio.run(play(driver, int(RATE * 1.2)))
    tolerance = driver.compliance.quantum_mm / 2 + 1e-12
    worst = max(float(np.abs(f.displacement - truth).max()) for f, truth in pairs)
    assert worst <= tolerance
    depths = np.array([truth[:, 2].min() for _, truth in pairs])
    assert depths.min() < -1.8  # the press, at full depth (its centre falls between taxels)
    assert (depths == 0).sum() > 5  # and rest frames are rest
    for f, _ in pairs:
        np.testing.assert_allclose(f.pressure, -f.displacement[:, 2] / driver.compliance.mm_per_count
                                   * driver.compliance.kpa_per_count)
    c = driver.counters
    assert c.frames >= len(pairs) and c.bad_crc == c.truncated == 0
    assert c.lost <= driver.simulator.frames_dropped  # a gap only if the board overran a full pty
    assert driver.health().state == Health.disconnected and driver.health().reason == "closed"


def test_shear_is_lost_but_the_normal_component_is_recovered():
    mesh = flat_pad(6, 6, pitch_mm=4.0, clamp_border=False)
    scene = Scene.from_dict({"step": [{"kind": "slide", "at": [4.0, 10.0, 0.0], "to": [16.0, 10.0, 0.0],
                                       "depth_mm": 1.0, "shear_mm": 0.5, "radius_mm": 8.0}]})
    compliance = Compliance(69.0, 3.0, 0.01)
    sim = TaxelSimulator(scene, mesh, (6, 6), compliance, rate_hz=100)
    counts, truth = sim.frame(50)
    assert np.abs(truth[:, :2]).max() > 0.1  # there is shear in the ground truth
    recovered = compliance.normal_mm(counts.ravel())
    np.testing.assert_allclose(recovered, -truth[:, 2], atol=compliance.quantum_mm / 2 + 1e-12)


def test_compliance_round_trip_and_saturation():
    c = Compliance(modulus_kpa=69.0, thickness_mm=3.0, kpa_per_count=0.01)
    d = np.linspace(0, 5, 1001)
    assert np.abs(c.normal_mm(c.counts(d)) - d).max() <= c.quantum_mm / 2 + 1e-12
    assert c.counts(np.array([-1.0, c.full_scale_mm * 2]))[0] == 0  # a taxel cannot feel a pull
    assert c.counts(np.array([c.full_scale_mm * 2]))[0] == 65535
    with pytest.raises(ValueError):
        Compliance(0.0, 3.0, 0.01)


def test_the_driver_survives_its_board_being_unplugged(tmp_path):
    mesh = flat_pad(4, 4, pitch_mm=4.0, clamp_border=False)
    scene = Scene.from_dict({"scene": {"loop": True}, "step": [
        {"kind": "press", "at": [6.0, 6.0, 0.0], "start_s": 0.0, "duration_s": 0.5, "depth_mm": 1.0}]})
    compliance = Compliance(69.0, 3.0, 0.01)
    sim = TaxelSimulator(scene, mesh, (4, 4), compliance, rate_hz=RATE, link=tmp_path / "ttyTAXEL")
    driver = open_taxel_device(DeviceConfig("u", "taxel-array", {"simulate": True, "rows": 4, "cols": 4,
                                                                 "backoff_initial_s": 0.01,
                                                                 "backoff_cap_s": 0.05}))
    driver = TaxelDriver(driver.description, shape=(4, 4), compliance=compliance, simulator=sim,
                         backoff=driver._backoff)
    states = []  # every disconnected state the driver went through, in order (polling can miss one)
    set_health = driver.set_health

    def record(state, reason=""):
        set_health(state, reason)
        if state == Health.disconnected and (not states or states[-1].reason != reason):
            states.append(driver.health())

    driver.set_health = record

    async def unplug_and_replug():
        while driver.counters.frames < 20:
            await asyncio.sleep(0.005)
        sim.unplug()
        while not driver.health().reason.startswith("cannot open"):  # the path is gone: re-opens fail
            await asyncio.sleep(0.005)
        # the consumer must have every frame decoded before the unplug: the replugged board restarts
        # at seq 0 and its old ground truth is gone
        while len(pairs) < driver.counters.frames:
            await asyncio.sleep(0.005)
        sim.replug()

    pairs: list = []

    async def main():
        side = asyncio.create_task(unplug_and_replug())
        await asyncio.wait_for(play(driver, 60, pairs), 60)
        await side
        return pairs

    pairs = asyncio.run(main())
    assert states[0].reason.startswith("lost ") and states[1].reason.startswith("cannot open ")
    assert all(st.state == Health.disconnected for st in states)
    assert driver.counters.reconnects == 1 and driver.counters.bad_crc == 0
    worst = max(float(np.abs(f.displacement - truth).max()) for f, truth in pairs)
    assert worst <= compliance.quantum_mm / 2 + 1e-12


@pytest.mark.parametrize(("settings", "message"), [
    ({}, "setting 'port': required setting is missing"),
    ({"port": "/dev/ttyUSB0", "baud": 9600}, "setting 'baud': unknown setting"),
    ({"port": "/dev/ttyUSB0", "protocol": "modbus"}, "setting 'protocol': 'modbus' is not one of"),
    ({"port": "/dev/ttyUSB0", "rows": 255, "cols": 255}, "setting 'rows': 255 x 255 taxels do not fit"),
    ({"simulate": True, "scene": "/no/such.toml"}, "setting 'scene': /no/such.toml"),
])
def test_bad_settings_name_the_field(registry, settings, message):
    with pytest.raises(DriverError) as e:
        registry.open_device(DeviceConfig("t", "taxel-array", settings))
    assert str(e.value).startswith(f"device 't' (family 'taxel-array'): {message}")


def test_the_demo_device_opens_and_streams(registry):
    (cfg,) = registry.demo_devices()
    driver = registry.open_device(cfg)
    assert driver.description.mesh.n_nodes == 256 and driver.simulator is not None
    pairs = asyncio.run(play(driver, 5))
    assert len(pairs) == 5


def test_the_pressure_grid_is_the_last_frames_as_rows_by_cols(registry, tmp_path):
    """ServesRawSignals (issue 29): the grid read on demand is the frame's pressure, rows x cols, a view."""
    from wott_hub.plugin_api import RawSignal, ServesRawSignals

    scene_file = tmp_path / "e2e.toml"
    scene_file.write_text(SCENE)
    cfg = DeviceConfig("t1", "taxel-array", {"simulate": True, "scene": str(scene_file), "rate_hz": RATE,
                                              "rows": 8, "cols": 10})
    driver = registry.open_device(cfg)
    assert isinstance(driver, ServesRawSignals)
    assert driver.raw_signals == (RawSignal("pressure", "grid", (8, 10), unit="kPa", rate_hz=RATE),)
    assert driver.raw_sample("pressure") is None  # before the first frame

    async def pressed():
        async for f in driver.frames():
            sample = driver.raw_sample("pressure")
            assert sample is not None and sample.t_ns == f.t_ns
            assert sample.array.shape == (8, 10) and np.shares_memory(sample.array, f.pressure)
            np.testing.assert_array_equal(sample.array.ravel(), f.pressure)  # row-major: node r * cols + c
            if f.pressure.max() > 0:
                break
        await driver.close()

    asyncio.run(asyncio.wait_for(pressed(), 30))
    assert driver.raw_sample("temperature") is None
