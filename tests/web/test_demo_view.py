"""The demo scenes press where the device page's default camera looks (issue 18: a new user saw
nothing move on the barrel, whose press and slide were on the far side)."""

from __future__ import annotations

import re
from importlib import resources

import numpy as np
import pytest

from wott_hub.examples import example_device
from wott_hub.plugins.demo import _demo_steps


def camera_side() -> np.ndarray:
    """The horizontal direction the default camera looks from, read from render3d.js."""
    src = (resources.files("wott_hub.web") / "static" / "render3d.js").read_text()
    eye = [float(v) for v in re.search(r"export const EYE = \[([^\]]+)\]", src).group(1).split(",")]
    side = np.array([eye[0], eye[1], 0.0])
    return side / np.linalg.norm(side)


def points(steps: list[dict]) -> np.ndarray:
    return np.array([s[k] for s in steps for k in ("at", "to") if k in s], dtype=float)


@pytest.mark.parametrize("shape", ["barrel", "cylinder"])
def test_built_in_scene_steps_are_on_the_half_the_camera_sees(shape):
    mesh = example_device(shape).mesh
    axis = mesh.nodes[mesh.free_indices].mean(axis=0)
    facing = (points(_demo_steps(mesh)) - axis) @ camera_side()
    assert (facing > 0).all(), facing


def test_every_step_of_the_barrel_plugin_demo_scene_faces_the_camera():
    from wott_driver_barrel.settings import demo_scene_path

    from wott_hub.sim.scene import Scene

    scene = Scene.load(demo_scene_path())
    side = camera_side()
    kinds = {s.kind for s in scene.steps}
    assert {"press", "slide"} <= kinds
    for step in scene.steps:
        for p in (step.at, step.to):
            if p is None:
                continue
            xy = np.array([p[0], p[1], 0.0]) / np.hypot(p[0], p[1])
            # within 60 degrees of the camera's azimuth: in plain view, not on the rim
            assert xy @ side > 0.5, (step.kind, p)
