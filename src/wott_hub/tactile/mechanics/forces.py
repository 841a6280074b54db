"""Contact forces from measured displacements, through the skin's assembled stiffness.

At equilibrium the external force on every node is f = K u (+ C u̇ + M ü while
the skin moves). A node away from any contact feels no external force, so the
force on a contact patch is the sum of f over its nodes: edge springs inside
the patch cancel pairwise and only the foundation under the patch and the
edges crossing its border remain. That is what the Winkler model leaves out
(it sees the foundation only) and why it errs on both spread-out and sharp
presses. The estimate is exact for a quasi-static press measured without
noise on the model's own skin; the benchmark reports what dynamics, noise,
the ε threshold and a wrong modulus do to it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..mesh import SkinMesh
from .model import MechanicsError, SkinModel, SkinParams

__all__ = ["DynamicForceEstimator", "StiffnessForceModel", "nodal_forces"]


def nodal_forces(model: SkinModel, displacement: np.ndarray, velocity: np.ndarray | None = None,
                 acceleration: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) external force each node needs for this motion: K u + τ K u̇ + M ü, in N.

    Clamped nodes get their mount reaction; ``velocity``/``acceleration`` are
    (N, 3) like ``displacement`` and optional (quasi-static when omitted).
    """
    d = np.asarray(displacement, dtype=float)
    n = model.mesh.n_nodes
    if d.shape != (n, 3):
        raise MechanicsError(f"expected an ({n}, 3) displacement, got {d.shape}")
    f = model.K_full @ d.ravel()
    if velocity is not None:
        f = f + model.params.damping_time_s * (model.K_full @ np.asarray(velocity, dtype=float).ravel())
    if acceleration is not None:
        acc = np.asarray(acceleration, dtype=float)
        f = f.reshape(n, 3)
        f[model.nodes] += model.mass.reshape(-1, 3) * acc[model.nodes]
        if model.params.mass_damping_per_s and velocity is not None:
            f[model.nodes] += (model.params.mass_damping_per_s * model.mass.reshape(-1, 3)
                               * np.asarray(velocity, dtype=float)[model.nodes])
    return np.asarray(f).reshape(n, 3)


class StiffnessForceModel:
    """Force on a contact patch = Σ over its nodes of (K d)_i: a drop-in for ``WinklerForceModel``.

    The stiffness is assembled once; each frame with contacts costs one sparse
    product (K d), shared by all the frame's patches.
    """

    def __init__(self, mesh: SkinMesh, modulus_mpa: float, thickness_mm: float, **params: Any) -> None:
        self.model = SkinModel(mesh, SkinParams(modulus_mpa=modulus_mpa, thickness_mm=thickness_mm, **params))
        self._k = self.model.K_full
        self._last: np.ndarray | None = None
        self._last_f: np.ndarray | None = None

    @classmethod
    def from_model(cls, model: SkinModel) -> StiffnessForceModel:
        self = cls.__new__(cls)
        self.model, self._k, self._last, self._last_f = model, model.K_full, None, None
        return self

    def node_forces(self, displacement: np.ndarray) -> np.ndarray:
        f = self._last_f
        if f is None or displacement is not self._last:  # one product per frame, however many patches
            f = np.asarray(self._k @ displacement.ravel()).reshape(-1, 3)
            self._last_f, self._last = f, displacement
        return f

    def force(self, nodes: np.ndarray, displacement: np.ndarray) -> np.ndarray:
        force: np.ndarray = self.node_forces(displacement)[nodes].sum(axis=0)
        return force


class DynamicForceEstimator:
    """Adds the Kelvin-Voigt damping force τ K u̇ from the previous frame (backward difference).

    Inertia is left out on purpose: a second difference of measured
    displacements amplifies their noise by 1/h² and the skin's inertial force
    is small at frame rates (the benchmark shows both).
    """

    def __init__(self, model: SkinModel) -> None:
        self.model = model
        self._prev: tuple[float, np.ndarray] | None = None

    def update(self, t_s: float, displacement: np.ndarray) -> np.ndarray:
        """(N, 3) estimated external force on every node at time ``t_s``."""
        d = np.asarray(displacement, dtype=float)
        v = None
        if self._prev is not None and t_s > self._prev[0]:
            v = (d - self._prev[1]) / (t_s - self._prev[0])
        self._prev = (t_s, d)
        return nodal_forces(self.model, d, v)
