"""Training and test data for the displacement model, from the simulator.

A sample is one random touch: one to three spherical indenters at uniformly
random places of the free skin (height 35-225 mm, any azimuth), radius 8-20
mm, depth up to 8 mm (a palm-sized press on a 10 cm barrel), optionally
dragging the skin tangentially by up to 1.5 mm; the ground truth is the
indentation model (``wott_hub.tactile.indentation``), as the scenes use. The
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

from wott_hub.tactile.indentation import Indenter, indent

from .geometry import BarrelLayout, _ray_mesh

__all__ = ["ContactSampler", "Dataset", "make_dataset"]


@dataclass(frozen=True)
class ContactSampler:
    z_range_mm: tuple[float, float] = (35.0, 225.0)
    radius_range_mm: tuple[float, float] = (8.0, 20.0)
    depth_range_mm: tuple[float, float] = (0.3, 8.0)
    max_shear_mm: float = 1.5
    contacts_p: tuple[float, float, float] = (0.6, 0.3, 0.1)  # P(1, 2, 3 contacts)

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
            shear *= rng.uniform(0, self.max_shear_mm) / max(np.linalg.norm(shear), 1e-9)
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


def make_dataset(layout: BarrelLayout, n: int, *, seed: int = 0, sampler: ContactSampler | None = None,
                 rest_fraction: float = 0.05) -> Dataset:
    """``n`` samples with exact marker displacements (add detector noise in training, not here)."""
    rng = np.random.default_rng(seed)
    sampler = sampler or ContactSampler()
    mesh = layout.mesh
    free = mesh.free_indices
    feats = np.zeros((n, layout.n_features), np.float32)
    targets = np.zeros((n, 3 * len(free)), np.float32)
    truth = np.zeros((n, mesh.n_nodes, 3), np.float32)
    for i in range(n):
        if rng.random() < rest_fraction:
            continue  # the skin at rest must map to zero
        d = indent(mesh, sampler.indenters(layout, rng))
        truth[i] = d
        targets[i] = d[free].ravel()
        feats[i] = layout.features(d)
    return Dataset(feats, targets, truth)
