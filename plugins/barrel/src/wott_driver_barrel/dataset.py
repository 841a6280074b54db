"""Training and test data for the displacement model, from the simulator.

A sample is one random touch: one to three spherical indenters at uniformly
random places of the free skin (height 35-225 mm, any azimuth), radius 8-20
mm, depth up to 8 mm (a palm-sized press on a 10 cm barrel), optionally
dragging the skin tangentially by up to 1.5 mm; the ground truth is the
Kelvin-Voigt skin (``model = "kelvin-voigt"``, the mechanics the simulators
use; solved quasi-statically through a ``Scene``, so only the plugin API is
needed), or the older indentation model with ``model = "indentation"`` (kept
for the before/after comparison in docs/barrel-vision.md). The
input is what the tracker reports for it: the image displacement of every
marker in both cameras, either exactly (the camera model, fast: thousands of
samples per second) or through the real chain (render both images, detect,
track: what the driver sees, about 10 ms a sample).

The same generator, with another seed, makes the held-out set the docs and
the benchmark report accuracy on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wott_hub.plugin_api import Indenter, Scene, indent

from .geometry import BarrelLayout, _ray_mesh

__all__ = ["GROUND_TRUTHS", "ContactSampler", "Dataset", "make_dataset"]

GROUND_TRUTHS = ("kelvin-voigt", "indentation")
_CHUNK = 200  # samples per Kelvin-Voigt scene: one skin model assembled per chunk


@dataclass(frozen=True)
class ContactSampler:
    z_range_mm: tuple[float, float] = (35.0, 225.0)
    radius_range_mm: tuple[float, float] = (8.0, 20.0)
    depth_range_mm: tuple[float, float] = (0.3, 8.0)
    max_shear_mm: float = 1.5
    contacts_p: tuple[float, float, float] = (0.6, 0.3, 0.1)  # P(1, 2, 3 contacts)
    material: str = "ecoflex-00-30"  # Kelvin-Voigt skin: the demo scene's material and thickness
    thickness_mm: float = 3.0

    def indenters(self, layout: BarrelLayout, rng: np.random.Generator) -> list[Indenter]:
        mesh = layout.mesh
        n = int(rng.choice(len(self.contacts_p), p=self.contacts_p)) + 1
        z = rng.uniform(*self.z_range_mm, n)
        az = rng.uniform(0, 2 * np.pi, n)
        origin = np.column_stack([np.zeros(n), np.zeros(n), z])
        direction = np.column_stack([np.cos(az), np.sin(az), np.zeros(n)])
        _, _, t = _ray_mesh(origin, direction, mesh.nodes, mesh.cells)
        centres = origin + t[:, None] * direction
        out = []
        for c in centres:
            shear = rng.normal(size=3)
            shear *= rng.uniform(0, self.max_shear_mm) / max(float(np.linalg.norm(shear)), 1e-9)
            if rng.random() < 0.5:
                shear[:] = 0.0
            out.append(Indenter(c, float(rng.uniform(*self.depth_range_mm)),
                                float(rng.uniform(*self.radius_range_mm)), shear))
        return out


@dataclass
class Dataset:
    features: np.ndarray  # (S, n_features) float32, px
    targets: np.ndarray  # (S, 3 * n_free) float32, mm
    truth: np.ndarray  # (S, N, 3) float32, mm: all nodes


def _steps(layout: BarrelLayout, touches: list[list[Indenter]]) -> list[dict[str, object]]:
    """Scene steps playing touch ``k`` in the window [k, k + 0.8] s, at full depth at k + 0.4 s.

    A dragged contact is a ``slide`` whose end point is 0.01 mm away along the
    (tangential part of the) drag: the scene's sticky shear, the indenter still.
    """
    normals, nodes = layout.mesh.normals, layout.mesh.nodes
    out: list[dict[str, object]] = []
    for k, indenters in enumerate(touches):
        for ind in indenters:
            step: dict[str, object] = {"kind": "press", "at": [float(v) for v in ind.centre],
                                       "start_s": float(k), "duration_s": 0.8, "ramp_s": 0.1,
                                       "depth_mm": float(ind.depth_mm), "radius_mm": float(ind.radius_mm)}
            shear = np.asarray(ind.shear, dtype=float)
            n = normals[int(np.argmin(np.linalg.norm(nodes - ind.centre, axis=1)))]
            tangential = shear - (shear @ n) * n
            size = float(np.linalg.norm(tangential))
            if size > 1e-6:
                step.update(kind="slide", shear_mm=size,
                            to=[float(v) for v in ind.centre + 0.01 * tangential / size])
            out.append(step)
    return out


def _kelvin_voigt(layout: BarrelLayout, touches: list[list[Indenter]],
                  sampler: ContactSampler) -> list[np.ndarray | None]:
    """Quasi-static Kelvin-Voigt displacement of each touch (None: the contact solver gave up)."""
    scene = Scene.from_dict({"scene": {"name": "barrel-training", "model": "kelvin-voigt",
                                       "material": sampler.material, "thickness_mm": sampler.thickness_mm},
                             "step": _steps(layout, touches)})
    out: list[np.ndarray | None] = []
    for k in range(len(touches)):
        try:
            out.append(np.array(scene.displacement_at(k + 0.4, layout.mesh)))
        except ValueError:  # a ContactError (overlapping indenters the solver cannot share)
            out.append(None)
    return out


def make_dataset(layout: BarrelLayout, n: int, *, seed: int = 0, sampler: ContactSampler | None = None,
                 rest_fraction: float = 0.05, model: str = "kelvin-voigt") -> Dataset:
    """``n`` samples with exact marker displacements (add detector noise in training, not here)."""
    if model not in GROUND_TRUTHS:
        raise ValueError(f"model: {model!r} is not one of {', '.join(GROUND_TRUTHS)}")
    rng = np.random.default_rng(seed)
    sampler = sampler or ContactSampler()
    mesh = layout.mesh
    free = mesh.free_indices
    feats = np.zeros((n, layout.n_features), np.float32)
    targets = np.zeros((n, 3 * len(free)), np.float32)
    truth = np.zeros((n, mesh.n_nodes, 3), np.float32)
    # the skin at rest must map to zero: those samples stay all-zero
    touched = [i for i in range(n) if rng.random() >= rest_fraction]
    touches = {i: sampler.indenters(layout, rng) for i in touched}
    if model == "indentation":
        solved: dict[int, np.ndarray | None] = {i: indent(mesh, touches[i]) for i in touched}
    else:
        solved = {}
        for c in range(0, len(touched), _CHUNK):
            chunk = touched[c : c + _CHUNK]
            found = _kelvin_voigt(layout, [touches[i] for i in chunk], sampler)
            solved.update(zip(chunk, found, strict=True))
    for i in touched:
        d = solved[i]
        if d is None:  # rare: replaced by its first contact alone
            d = _kelvin_voigt(layout, [touches[i][:1]], sampler)[0]
            if d is None:
                continue
        truth[i] = d
        targets[i] = d[free].ravel()
        feats[i] = layout.features(d)
    return Dataset(feats, targets, truth)
