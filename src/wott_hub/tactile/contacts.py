"""Contacts: connected patches of deformed nodes, with location and force."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .mesh import SkinMesh

__all__ = ["Contact", "ForceModel", "WinklerForceModel", "find_contacts", "group_patches"]

# Above this many deformed nodes SciPy's compiled search beats the Python walk (its fixed cost,
# ~0.1 ms of sparse-matrix set-up, is paid back); below it the walk is 1.4-20x faster.
# Measured by `wott-hub bench processing` (docs/benchmarks.md, "Finding contact patches").
WALK_MAX_NODES = 400


class ForceModel(Protocol):
    """Anything that turns a patch's displacements into the force on it (N, into the skin)."""

    def force(self, nodes: np.ndarray, displacement: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True, slots=True, eq=False)
class Contact:
    """One contact patch: its nodes, where it is and the force the skin feels there."""

    nodes: np.ndarray  # mesh node indices, ascending
    location: np.ndarray  # (3,) intensity-weighted mean rest position, mm
    force: np.ndarray  # (3,) N, pushing into the skin
    intensity: float  # sum of the nodes' displacement norms, mm
    peak: float  # largest displacement norm in the patch, mm
    shear: np.ndarray  # (3,) mean tangential displacement, mm
    depth: float  # mean normal displacement magnitude, mm


class WinklerForceModel:
    """Force from displacement by a bed of independent springs under the skin.

    Each node is a spring to ground of stiffness k_i = E · A_i / h (Young's
    modulus, the node's lumped area, the skin thickness), so the force on a
    patch is Σ k_i D_i. It ignores the coupling between neighbours: it
    overestimates spread-out presses and underestimates sharp ones; the
    mechanics module's stiffness-based estimator replaces it where accuracy
    matters. It is cheap: one multiply-add over the patch.
    """

    def __init__(self, mesh: SkinMesh, modulus_mpa: float, thickness_mm: float) -> None:
        if modulus_mpa <= 0 or thickness_mm <= 0:
            raise ValueError("modulus and thickness must be positive")
        self.node_stiffness = modulus_mpa * mesh.node_areas / thickness_mm  # N/mm

    def force(self, nodes: np.ndarray, displacement: np.ndarray) -> np.ndarray:
        force: np.ndarray = self.node_stiffness[nodes] @ displacement[nodes]
        return force


def group_patches(mesh: SkinMesh, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Connected components of the mesh graph restricted to ``nodes`` (ascending).

    Returns ``nodes`` grouped by component (ascending within each, components
    in order of their smallest node) and the size of each component.
    """
    if len(nodes) > WALK_MAX_NODES:
        from scipy.sparse.csgraph import connected_components

        n, labels = connected_components(mesh.adjacency[nodes][:, nodes], directed=False)
        return nodes[np.argsort(labels, kind="stable")], np.bincount(labels, minlength=n)
    neighbours = mesh.neighbour_lists
    remaining = set(nodes.tolist())
    grouped: list[int] = []
    sizes: list[int] = []
    for start in nodes.tolist():
        if start not in remaining:
            continue
        remaining.discard(start)
        patch = [start]
        stack = [start]
        while stack:
            found = remaining.intersection(neighbours[stack.pop()])
            if found:
                remaining -= found
                patch.extend(found)
                stack.extend(found)
        patch.sort()
        grouped += patch
        sizes.append(len(patch))
    return np.array(grouped, dtype=np.int64), np.array(sizes, dtype=np.int64)


def find_contacts(
    mesh: SkinMesh,
    deformed: np.ndarray,
    intensity: np.ndarray,
    displacement: np.ndarray,
    force_model: ForceModel,
    min_nodes: int = 1,
) -> list[Contact]:
    """Split the deformed nodes into connected patches on the mesh graph.

    ``deformed`` holds node indices (ascending), ``intensity`` the displacement
    norm of every node. Patches smaller than ``min_nodes`` are dropped as noise.
    Each statistic is computed for all patches at once (``reduceat`` over the
    nodes grouped by patch): a frame costs the same few array operations
    whether it has one contact or ten.
    """
    if deformed.size == 0:
        return []
    nodes, counts = group_patches(mesh, deformed)
    starts = np.concatenate(([0], np.cumsum(counts[:-1])))
    w = intensity[nodes]
    total = np.add.reduceat(w, starts)
    location = np.add.reduceat(w[:, None] * mesh.nodes[nodes], starts) / total[:, None]
    peak = np.maximum.reduceat(w, starts)
    d = displacement[nodes]
    n = mesh.normals[nodes]
    normal = np.einsum("ij,ij->i", d, n)
    shear = np.add.reduceat(d - normal[:, None] * n, starts) / counts[:, None]
    depth = np.add.reduceat(np.abs(normal), starts) / counts
    contacts = []
    for c in np.argsort(-total, kind="stable").tolist():
        if counts[c] < min_nodes:
            continue
        patch = nodes[starts[c] : starts[c] + counts[c]]
        contacts.append(
            Contact(
                nodes=patch,
                location=location[c],
                force=force_model.force(patch, displacement),
                intensity=float(total[c]),
                peak=float(peak[c]),
                shear=shear[c],
                depth=float(depth[c]),
            )
        )
    return contacts
