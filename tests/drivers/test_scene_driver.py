"""The scene driver replays a looping scene's frames instead of simulating every loop again
(drivers/scene.py): only where the scene repeats exactly, and with the frames it would compute."""

from __future__ import annotations

import asyncio

import numpy as np

from wott_hub.drivers.scene import SceneDriver
from wott_hub.examples import example_device
from wott_hub.sim.scene import Scene


def _scene(duration_s: float, **head) -> Scene:
    desc = example_device("flat")
    at = [float(v) for v in desc.mesh.nodes[desc.mesh.free_indices[100]]]
    return Scene.from_dict({"scene": {"loop": True, **head}, "step": [
        {"kind": "press", "at": at, "start_s": 0.0, "duration_s": duration_s - 0.25, "depth_mm": 1.0,
         "radius_mm": 4.0}]})


def _frames(driver: SceneDriver, n: int) -> list:
    async def take():
        out = []
        async for f in driver.frames():
            out.append(f)
            if len(out) == n:
                break
        return out
    return asyncio.run(take())


def test_a_looping_scene_of_a_whole_number_of_frames_is_simulated_once_and_replayed():
    desc = example_device("flat")
    scene = _scene(0.5)  # 0.25 s press + 0.25 s rest tail: 60 frames at 120 Hz
    driver = SceneDriver(desc, scene, 120.0, realtime=False)
    frames = _frames(driver, 180)
    assert driver._loop_frames == 60
    for k in (3, 30, 59):
        assert frames[k + 60].displacement is frames[k].displacement  # replayed, not recomputed
        np.testing.assert_array_equal(frames[k + 120].displacement, scene.displacement_at(k / 120, desc.mesh))
    assert frames[61].t_ns - frames[1].t_ns == 500_000_000  # time goes on: only the values repeat


def test_scenes_that_do_not_repeat_frame_for_frame_are_simulated_every_frame():
    desc = example_device("flat")
    assert SceneDriver(desc, _scene(0.505), 120.0)._loop_frames == 0  # 60.6 frames per loop
    assert SceneDriver(desc, _scene(0.5, model="kelvin-voigt"), 120.0)._loop_frames == 0  # has state
    assert SceneDriver(desc, _scene(0.5, loop=False), 120.0)._loop_frames == 0  # played once


def test_a_closed_driver_stops_within_a_frame_even_between_short_waits():
    desc = example_device("flat")
    driver = SceneDriver(desc, _scene(0.5), 120.0)

    async def run() -> None:
        got = []

        async def consume():
            async for f in driver.frames():
                got.append(f)

        task = asyncio.create_task(consume())
        await asyncio.sleep(0.1)
        await driver.close()
        # a looping scene: a driver that kept going would never end (30 s: a hang's bound, not a speed)
        await asyncio.wait_for(task, 30.0)
        assert got  # it was running

    asyncio.run(run())
