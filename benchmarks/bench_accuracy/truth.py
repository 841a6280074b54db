"""What the scene says happened at each frame: where the fingers were, how hard, how fast.

``steady``: every finger touching is at its full depth (no ramp in or out), so the right
number of contacts is the number of fingers. ``rest``: nothing touches: any contact is a
phantom. The force a contact should report is the one the device's own force model gives
for the true displacement of the nodes that finger deforms (each deformed node to the
finger whose bump is largest there): that isolates what segmentation and the estimate do
to the force from the force model's own error (bench mechanics scores that).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wott_hub.sim.scene import Scene
from wott_hub.tactile import SkinMesh, WinklerForceModel
from wott_hub.tactile.processing import processing_params

from .families import Recording

__all__ = ["FrameTruth", "frame_truths", "release_speed", "slip_speed"]


@dataclass(frozen=True)
class FrameTruth:
    centres: np.ndarray  # (k, 3) mm, the fingers touching
    forces: np.ndarray  # (k,) N, |force| each finger's nodes carry under the device's force model
    steady: bool
    rest: bool


def _levels(scene: Scene, t: float) -> list[float]:
    """The level (0-1) of every indenter touching at ``t``, in ``Scene.indenters_at`` order."""
    out = []
    for s in scene.steps:
        level = s.level_at(t)
        if level > 0:
            out += [level] * (2 if s.kind == "pinch" else 1)
    return out


def frame_truths(rec: Recording) -> list[FrameTruth]:
    mesh, scene = rec.description.mesh, rec.scene
    p = processing_params(rec.description)
    force = WinklerForceModel(mesh, p.modulus_mpa, p.thickness_mm)
    eps = rec.description.epsilon_mm
    out = []
    for t in rec.scene_t:
        inds = scene.indenters_at(t, mesh)
        levels = _levels(scene, t)
        centres = np.array([i.centre for i in inds]).reshape(-1, 3)
        forces = np.zeros(len(inds))
        if inds:
            d = scene.displacement_at(t, mesh)
            forces = _finger_forces(mesh, d, inds, force, eps)
        out.append(FrameTruth(centres, forces, bool(levels) and min(levels) >= 1.0, not inds))
    return out


def _finger_forces(mesh: SkinMesh, d: np.ndarray, inds: list, force: WinklerForceModel, eps: float
                   ) -> np.ndarray:
    deformed = np.flatnonzero((np.linalg.norm(d, axis=1) > eps) & mesh.free)
    bumps = np.array([ind.depth_mm * np.exp(-((mesh.nodes[deformed] - ind.centre) ** 2).sum(axis=1)
                                            / (2 * (ind.radius_mm / 2) ** 2)) for ind in inds])
    owner = np.argmax(bumps, axis=0) if len(deformed) else np.empty(0, int)
    return np.array([float(np.linalg.norm(force.force(deformed[owner == j], d))) for j in range(len(inds))])


def _finger_speed(scene: Scene, mesh: SkinMesh, t: float, dt: float = 1e-3) -> float:
    """Mean speed (mm/s) of the fingers touching at ``t`` (central difference of their centres)."""
    a, b = scene.indenters_at(t - dt, mesh), scene.indenters_at(t + dt, mesh)
    if not a or len(a) != len(b):
        return 0.0
    return float(np.mean([np.linalg.norm(y.centre - x.centre) / (2 * dt) for x, y in zip(a, b, strict=True)]))


def release_speed(scene: Scene, mesh: SkinMesh) -> float:
    """How fast the last finger moved over the skin as it lifted (0 for a press)."""
    last = max(scene.steps, key=lambda s: s.end_s)
    return _finger_speed(scene, mesh, last.end_s - min(last.ramp_s, last.duration_s / 2) / 2)


def slip_speed(scene: Scene, mesh: SkinMesh) -> float:
    """A slide's speed mid-way (mm/s), 0 without a slide."""
    slides = [s for s in scene.steps if s.kind == "slide"]
    return _finger_speed(scene, mesh, slides[0].start_s + slides[0].duration_s / 2) if slides else 0.0
