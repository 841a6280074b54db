"""Contacts: connected patches of deformed nodes, with location and force."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.sparse.csgraph import connected_components

from .mesh import SkinMesh

__all__ = ["Contact", "ForceModel", "WinklerForceModel", "find_contacts"]


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
        return self.node_stiffness[nodes] @ displacement[nodes]


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
    """
    if deformed.size == 0:
        return []
    sub = mesh.adjacency[deformed][:, deformed]
    n_comp, labels = connected_components(sub, directed=False)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n_comp + 1))
    normals = mesh.normals
    contacts = []
    for c in range(n_comp):
        nodes = deformed[order[bounds[c] : bounds[c + 1]]]
        if len(nodes) < min_nodes:
            continue
        w = intensity[nodes]
        total = float(w.sum())
        d = displacement[nodes]
        n = normals[nodes]
        normal = np.einsum("ij,ij->i", d, n)
        tangential = d - normal[:, None] * n
        contacts.append(
            Contact(
                nodes=nodes,
                location=(w @ mesh.nodes[nodes]) / total,
                force=force_model.force(nodes, displacement),
                intensity=total,
                peak=float(w.max()),
                shear=tangential.mean(axis=0),
                depth=float(np.abs(normal).mean()),
            )
        )
    contacts.sort(key=lambda k: -k.intensity)
    return contacts
