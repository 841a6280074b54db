"""Each family plays a case through its own driver; the frames are recorded with their scene time.

What a user's hub would get, frame for frame: the ``scene`` family's ground truth (the
example pad and the TacLink barrel, 120 Hz), the flat pad's and the barrel's simulated
cameras through detection, tracking and their models (60 and 30 frames/s, scene time as
fast as they go; in real time with ``realtime=True``, as a live camera: a busy machine then
drops frames and reads them late), and the taxel array over a real pty in real time (100 Hz),
so its frames carry the time stamps the hub really gets from a serial link. A recording keeps
the frames as the driver stamped them and, per frame, the scene time its truth belongs to: the
one the driver says it showed (the camera driver's ``last_truth_t_s``, the taxel simulator's
``scene_time`` of the frame's sequence number), never one guessed from the frame's time stamp.
"""

from __future__ import annotations

import asyncio
import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wott_hub.plugins import DeviceConfig, get_registry
from wott_hub.sim.scene import Scene
from wott_hub.tactile import DeviceDescription, TactileFrame

from .cases import Case

__all__ = ["FAMILIES", "Family", "Recording", "record"]


@dataclass(frozen=True)
class Recording:
    """One case played by one family's driver: what the processor will be given, and when in the scene."""

    family: str
    case: Case
    description: DeviceDescription
    scene: Scene
    frames: list[TactileFrame]
    scene_t: list[float]  # scene time (s) of each frame's truth
    driver: Any  # the closed driver, for what it declares (below_threshold_floor, ...)


@dataclass(frozen=True)
class Family:
    name: str  # as in the tables
    skin: str  # which case set (cases.CASES)
    rate_hz: float
    config: Callable[[str, Path, bool], DeviceConfig]  # (device id, scene file, realtime) -> its config


def _toml(data: dict[str, Any]) -> str:
    """The few value types a case has (numbers, strings, booleans, lists of numbers) as TOML."""
    lines = ["[scene]", *(f"{k} = {json.dumps(v)}" for k, v in data["scene"].items())]
    for step in data["step"]:
        lines += ["", "[[step]]", *(f"{k} = {json.dumps(v)}" for k, v in step.items())]
    return "\n".join(lines) + "\n"


def _scene_device(shape: str) -> Callable[[str, Path], DeviceConfig]:
    return lambda did, path, _realtime: DeviceConfig(did, "scene", {"shape": shape, "scene": str(path),
                                                                     "realtime": False, "rate_hz": 120.0})


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("scene pad", "pad", 120.0, _scene_device("flat")),
    Family("scene barrel", "barrel", 120.0, _scene_device("barrel")),
    Family("camera pad", "pad", 60.0, lambda did, path, realtime: DeviceConfig(
        did, "flat-vision", {"source": "sim", "scene": str(path), "fps": 60.0, "realtime": realtime})),
    Family("camera barrel", "barrel", 30.0, lambda did, path, realtime: DeviceConfig(
        did, "barrel-vision", {"source": "sim", "scene": str(path), "fps": 30.0, "realtime": realtime})),
    Family("taxel", "taxel", 100.0, lambda did, path, _realtime: DeviceConfig(
        did, "taxel-array", {"simulate": True, "scene": str(path), "rate_hz": 100.0})),
)}


async def _frames(driver: Any, family: Family, scene: Scene) -> tuple[list[TactileFrame], list[float]]:
    await driver.prepare()  # as the hub does after opening (the scene driver reads its file there)
    frames: list[TactileFrame] = []
    times: list[float] = []
    n_due = int(scene.duration_s * family.rate_hz) + 1
    async for frame in driver.frames():
        t = _scene_time(driver, frame, frames)
        if t is None:  # sent before the reader joined the line
            continue
        frames.append(frame)
        times.append(t)
        if len(frames) >= n_due or t >= scene.duration_s:
            break
    await driver.close()
    return frames, times


def _scene_time(driver: Any, frame: TactileFrame, frames: list[TactileFrame]) -> float | None:
    """The scene time of the frame ``driver`` just yielded: what its simulator says it showed."""
    simulator = getattr(driver, "simulator", None)
    if simulator is not None:  # the taxel board: by the frame's sequence number
        return None if driver.last_seq is None else simulator.scene_time(driver.last_seq)
    t_s = getattr(driver, "last_truth_t_s", None)
    if t_s is not None:  # a camera skin's simulated source
        return float(t_s)
    return (frame.t_ns - frames[0].t_ns) / 1e9 if frames else 0.0  # the scene driver: scene-time stamps


def record(family: Family, case: Case, index: int, *, realtime: bool = False) -> Recording:
    """Play ``case`` on ``family``'s driver (opened through the plugin registry, as the hub opens it);
    ``realtime``: the camera skins' sources paced as live cameras."""
    name = f"{family.skin}-{case.kind}-{case.placement}-{index}"
    data = case.scene(name)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{name}.toml"
        path.write_text(_toml(data))
        scene = Scene.load(path)
        driver = get_registry().open_device(family.config(name, path, realtime))
        frames, times = asyncio.run(asyncio.wait_for(_frames(driver, family, scene), 300))
    if not frames:
        raise RuntimeError(f"{family.name}: {case.kind}: no frame recorded")
    first = next((i for i, t in enumerate(times) if t >= 0), 0)
    return Recording(family.name, case, driver.description, scene, frames[first:], times[first:], driver)


def truth_displacement(rec: Recording, k: int) -> np.ndarray:
    """The scene's displacement at frame ``k`` of ``rec`` (N x 3 mm)."""
    return rec.scene.displacement_at(rec.scene_t[k], rec.description.mesh)
