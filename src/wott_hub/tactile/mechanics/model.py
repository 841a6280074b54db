"""The Kelvin-Voigt skin: mass, stiffness and damping of a mesh, ready to integrate.

Units are mm, N, s and tonnes (1 N = 1 t·mm/s², so masses are in tonnes and
no factor of 1000 hides anywhere). The model is linear about the rest shape
(small strains and rotations): its matrices never change, which is what lets
every implicit integrator factorise once and run at frame rate. Presses deeper
than a few edge lengths are extrapolated linearly; docs/mechanics.md says how
far that holds.

Clamped nodes are not degrees of freedom. Free nodes in no cell (no edge, no
area) cannot be moved by anything in the model: they are held fixed too and
listed in ``isolated_nodes`` rather than silently producing a singular matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from wott_hub.errors import InvalidInput

from ..materials import Material
from ..mesh import SkinMesh
from .assembly import assemble_blocks, edge_blocks, edge_set, foundation_blocks
from .probes import ProbeSet, build_probes

__all__ = [
    "ContactError",
    "MechanicsError",
    "SkinModel",
    "SkinParams",
    "StabilityError",
    "factorize",
]

MASS_FLOOR = 1e-3  # lightest node, in median node masses: a zero-area node still has inertia


class MechanicsError(InvalidInput):
    """An input the skin model cannot work with (bad parameters, singular skin, NaN...)."""


class StabilityError(MechanicsError):
    """An explicit step longer than the stable step; carries the stable step in seconds."""

    def __init__(self, message: str, stable_step_s: float) -> None:
        super().__init__(message)
        self.stable_step_s = stable_step_s


class ContactError(MechanicsError):
    """A press that cannot happen (deeper than a backed skin, a force with nothing to push on...)."""


@dataclass(frozen=True, slots=True)
class SkinParams:
    """Everything the model needs besides the mesh; see docs/mechanics.md for the defaults.

    ``foundation`` and ``shear_layer`` scale the Winkler bed (E/h per area) and
    the Vlasov shear layer (G h / 3); 0 removes them. ``pretension_n_per_mm``
    adds a membrane tension (an inflated skin). ``backed`` says the skin lies
    on a rigid backing at depth ``thickness_mm`` (a gel pad): no press can go
    deeper than that. ``probe_spacing_mm`` is the spacing of the contact probes
    on the faces (see ``probes``).
    """

    modulus_mpa: float
    thickness_mm: float
    density_kg_m3: float = 1070.0
    damping_time_s: float = 5e-4
    mass_damping_per_s: float = 0.0
    foundation: float = 1.0
    shear_layer: float = 1.0
    pretension_n_per_mm: float = 0.0
    backed: bool = False
    probe_spacing_mm: float = 2.0

    def __post_init__(self) -> None:
        positive = {"modulus_mpa": self.modulus_mpa, "thickness_mm": self.thickness_mm,
                    "density_kg_m3": self.density_kg_m3, "probe_spacing_mm": self.probe_spacing_mm}
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise MechanicsError(f"{name} must be a positive number, got {value}")
        non_negative = {"damping_time_s": self.damping_time_s, "mass_damping_per_s": self.mass_damping_per_s,
                        "foundation": self.foundation, "shear_layer": self.shear_layer,
                        "pretension_n_per_mm": self.pretension_n_per_mm}
        for name, value in non_negative.items():
            if not (math.isfinite(value) and value >= 0):
                raise MechanicsError(f"{name} must be a non-negative number, got {value}")

    @property
    def shear_modulus_mpa(self) -> float:
        return self.modulus_mpa / 3.0  # incompressible rubber

    @property
    def membrane_tension_n_per_mm(self) -> float:
        return self.shear_layer * self.shear_modulus_mpa * self.thickness_mm / 3.0 + self.pretension_n_per_mm


def factorize(a: sp.spmatrix) -> Any:  # a scipy SuperLU (SciPy ships no types)
    """Sparse LU of a symmetric positive definite matrix (symmetric ordering, no pivoting needed)."""
    a = sp.csc_matrix(a)
    try:
        lu = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError as e:  # "Factor is exactly singular"
        raise MechanicsError(f"the skin's matrix is singular ({e}): some free nodes are held by nothing; "
                             "keep a foundation, add pretension or clamp them") from None
    probe = np.linspace(1.0, 2.0, a.shape[0])
    x = lu.solve(a @ probe)
    if not np.isfinite(x).all() or np.linalg.norm(x - probe) > 1e-4 * np.linalg.norm(probe):
        raise MechanicsError("the skin's matrix is numerically singular: some free nodes are held by "
                             "nothing (no foundation, no tension, no path to a clamp)")
    return lu


@dataclass(eq=False)
class SkinModel:
    """Lumped masses, stiffness K and Kelvin-Voigt damping C = τK + αM on the free nodes.

    Vectors of degrees of freedom (``ndof`` = 3 x the number of moving nodes)
    are what integrators work on; ``to_nodes``/``to_dofs`` convert to and from
    the (N, 3) displacement of every mesh node.
    """

    mesh: SkinMesh
    params: SkinParams
    # mesh indices of the moving nodes (ascending); free nodes held fixed because nothing holds them
    nodes: np.ndarray = field(init=False, repr=False)
    isolated_nodes: np.ndarray = field(init=False, repr=False)
    K_full: sp.csr_matrix = field(init=False, repr=False)  # 3N x 3N over every mesh node (force estimation)
    K: sp.csr_matrix = field(init=False, repr=False)
    mass: np.ndarray = field(init=False, repr=False)  # (ndof,) tonnes
    slot: np.ndarray = field(init=False, repr=False)  # (N,) position of each node in ``nodes``, -1 if fixed

    def __post_init__(self) -> None:
        mesh, p = self.mesh, self.params
        edges = edge_set(mesh)
        e, g = p.modulus_mpa, p.shear_modulus_mpa
        blocks = edge_blocks(edges, e * p.thickness_mm, p.membrane_tension_n_per_mm)
        found = foundation_blocks(mesh, p.foundation * e / p.thickness_mm, p.foundation * g / p.thickness_mm)
        self.K_full = assemble_blocks(mesh.n_nodes, edges.pairs, blocks, found)
        has_edge = np.zeros(mesh.n_nodes, dtype=bool)
        has_edge[edges.pairs.ravel()] = True
        self.isolated_nodes = np.flatnonzero(mesh.free & ~has_edge)
        self.nodes = np.flatnonzero(mesh.free & has_edge)
        self.slot = np.full(mesh.n_nodes, -1, dtype=np.int64)
        self.slot[self.nodes] = np.arange(len(self.nodes))
        dofs = (3 * self.nodes[:, None] + np.arange(3)).ravel()
        self.K = self.K_full[dofs][:, dofs].tocsr()
        m = p.density_kg_m3 * 1e-12 * mesh.node_areas[self.nodes] * p.thickness_mm
        if len(m):
            floor = MASS_FLOOR * float(np.median(m[m > 0])) if (m > 0).any() else 1e-12
            m = np.maximum(m, floor)
        self.mass = np.repeat(m, 3)
        self._dofs = dofs

    @classmethod
    def from_material(cls, mesh: SkinMesh, material: Material, thickness_mm: float,
                      **options: Any) -> SkinModel:
        """A model whose modulus, density and damping come from a material (options override)."""
        params = SkinParams(
            modulus_mpa=material.modulus_mpa,
            thickness_mm=thickness_mm,
            density_kg_m3=material.density_kg_m3,
            damping_time_s=material.damping_time_s,
        )
        return cls(mesh, replace(params, **options))

    # -- sizes and conversions ------------------------------------------------------------
    @property
    def ndof(self) -> int:
        return 3 * len(self.nodes)

    @cached_property
    def C(self) -> sp.csr_matrix:
        """Kelvin-Voigt dashpots in parallel with every spring (τK), plus optional αM."""
        c = self.params.damping_time_s * self.K
        if self.params.mass_damping_per_s > 0:
            c = c + sp.diags(self.params.mass_damping_per_s * self.mass)
        return sp.csr_matrix(c)

    @cached_property
    def rest(self) -> np.ndarray:
        """(n, 3) rest positions of the moving nodes."""
        rest: np.ndarray = self.mesh.nodes[self.nodes]
        return rest

    @cached_property
    def normals(self) -> np.ndarray:
        normals: np.ndarray = self.mesh.normals[self.nodes]
        return normals

    @cached_property
    def probes(self) -> ProbeSet:
        return build_probes(self.mesh, self.params.probe_spacing_mm)

    @cached_property
    def probe_slots(self) -> np.ndarray:
        """(P, 3) model slots of each probe's nodes, -1 for a node that cannot move."""
        slots: np.ndarray = self.slot[self.probes.nodes]
        return slots

    @cached_property
    def probe_tree(self) -> Any:  # a scipy.spatial.cKDTree (SciPy ships no types)
        from scipy.spatial import cKDTree

        return cKDTree(self.probes.rest)

    @cached_property
    def probe_edge_mm(self) -> float:
        """Median length of the mesh edges (the scale of a face), mm."""
        e = self.mesh.edges
        lengths = np.linalg.norm(self.mesh.nodes[e[:, 1]] - self.mesh.nodes[e[:, 0]], axis=1)
        return float(np.median(lengths)) if len(lengths) else 0.0

    @cached_property
    def probe_moves(self) -> np.ndarray:
        """(P,) whether a probe has any weight on a moving node (an indenter can push it)."""
        return np.asarray(((self.probe_slots >= 0) & (self.probes.weights > 0)).any(axis=1))

    def to_nodes(self, x: np.ndarray) -> np.ndarray:
        """(N, 3) displacement of every mesh node from a dof vector (fixed nodes at zero)."""
        out = np.zeros((self.mesh.n_nodes, 3))
        out[self.nodes] = np.asarray(x).reshape(-1, 3)
        return out

    def to_dofs(self, d: np.ndarray) -> np.ndarray:
        d = np.asarray(d, dtype=float)
        if d.shape != (self.mesh.n_nodes, 3):
            raise MechanicsError(f"expected an ({self.mesh.n_nodes}, 3) displacement, got {d.shape}")
        dofs: np.ndarray = d[self.nodes].ravel().copy()
        return dofs

    # -- energy and stability ----------------------------------------------------------------
    def energy(self, u: np.ndarray, v: np.ndarray) -> float:
        """Kinetic plus elastic energy (N·mm = mJ)."""
        return 0.5 * float(v @ (self.mass * v)) + 0.5 * float(u @ (self.K @ u))

    @cached_property
    def omega_max(self) -> float:
        """Upper bound (Gershgorin) of the highest angular frequency of M⁻¹K, rad/s."""
        if self.ndof == 0:
            return 0.0
        s = 1.0 / np.sqrt(self.mass)
        scaled = sp.diags(s) @ abs(self.K) @ sp.diags(s)
        return math.sqrt(float(np.asarray(scaled.sum(axis=1)).max()))

    @cached_property
    def stable_step(self) -> float:
        """Longest step symplectic Euler takes without growing any mode, s.

        A mode ω with damping ratio ζ = (τω² + α)/(2ω) is stable for
        h ≤ 2 / (ω (√(1+ζ²) + ζ)) (the Jury conditions of the step's 2 x 2
        amplification matrix). The minimum over ω ≤ ω_max is taken on a grid
        because mass damping makes low modes the critical ones; 2 % is kept
        for round-off.
        """
        w_max = self.omega_max
        if w_max == 0:
            return math.inf
        tau, alpha = self.params.damping_time_s, self.params.mass_damping_per_s
        w = w_max * np.geomspace(1e-8, 1.0, 400)
        zeta = (tau * w**2 + alpha) / (2 * w)
        h = 2.0 / (w * (np.sqrt(1 + zeta**2) + zeta))
        return 0.98 * float(h.min())
