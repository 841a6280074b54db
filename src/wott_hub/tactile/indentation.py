"""A simple indentation model: the ground truth simulators use until the
Kelvin-Voigt skin (``wott_hub.tactile.mechanics``) is chosen by a scene.

Each indenter pushes the skin along the inward normal at its centre with a
Gaussian bump, w(r) = δ · exp(-r² / (2σ²)), σ = indenter radius / 2, r the
straight-line distance of a node's rest position from the centre, and drags the
patch tangentially by ``shear`` (mm, a vector) with the same profile. Clamped
nodes never move. It is smooth, cheap and has the right qualitative shape; it
is not mechanics (no force balance, no neighbour coupling).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mesh import SkinMesh

__all__ = ["Indenter", "indent"]


@dataclass(frozen=True, slots=True)
class Indenter:
    """A spherical tip at ``centre`` (a point on or near the rest surface, mm)."""

    centre: np.ndarray
    depth_mm: float
    radius_mm: float = 5.0
    shear: np.ndarray = field(default_factory=lambda: np.zeros(3))


def nearest_node(mesh: SkinMesh, point: np.ndarray) -> int:
    return int(np.argmin(np.linalg.norm(mesh.nodes - point, axis=1)))


def indent(mesh: SkinMesh, indenters: list[Indenter]) -> np.ndarray:
    """Displacement (N x 3, mm) of every node under the given indenters (superposed)."""
    d = np.zeros_like(mesh.nodes)
    for ind in indenters:
        if ind.depth_mm <= 0:
            continue
        centre = np.asarray(ind.centre, dtype=float)
        normal = mesh.normals[nearest_node(mesh, centre)]
        sigma = max(ind.radius_mm, 1e-6) / 2.0
        r2 = np.sum((mesh.nodes - centre) ** 2, axis=1)
        w = np.exp(-r2 / (2 * sigma**2))
        w[w < 1e-6] = 0.0
        shear = np.asarray(ind.shear, dtype=float)
        shear = shear - (shear @ normal) * normal
        d += w[:, None] * (-ind.depth_mm * normal + shear)[None, :]
    d[~mesh.free] = 0.0
    return d
