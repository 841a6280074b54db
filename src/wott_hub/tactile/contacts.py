"""Contacts: connected patches of deformed nodes, with location and force."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .mesh import SkinMesh

__all__ = ["Contact", "ContactFinder", "ForceModel", "WinklerForceModel", "find_contacts", "group_patches"]

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
    order = nodes.tolist()
    remaining = set(order)
    grouped: list[int] = []
    sizes: list[int] = []
    for start in order:
        if start not in remaining:
            continue
        remaining.remove(start)
        patch = [start]
        for node in patch:  # the list grows while it is read: a breadth-first walk, no stack
            for other in neighbours[node]:
                if other in remaining:
                    remaining.remove(other)
                    patch.append(other)
        if len(patch) == len(order):  # one patch (the common case): the nodes as they came
            return nodes.copy(), np.array([len(order)], dtype=np.int64)
        patch.sort()
        grouped += patch
        sizes.append(len(patch))
    return np.array(grouped, dtype=np.int64), np.array(sizes, dtype=np.int64)


_FIRST = np.zeros(1, dtype=np.intp)  # ``starts`` of a single patch
_FIRST.setflags(write=False)


def _node_table(mesh: SkinMesh) -> np.ndarray:
    """Per node, what a patch's statistics gather, (1, position | normal): one gather for both."""
    return np.column_stack([np.ones(mesh.n_nodes), mesh.nodes, mesh.normals])


class _Patches:
    """One deformed set split into patches, with what the statistics of any frame need of it.

    The per-node terms of the statistics are the columns of one (nodes x 8)
    array, weight x (1, position) | tangential displacement | normal depth, so
    one ``reduceat`` sums them all; a column sums exactly as the same values
    would alone, so the numbers are those of one reduction per statistic. The
    array is kept here and refilled each frame. The nodes' constants come from
    one gather of the finder's ``_node_table`` (a moving press makes a new set
    almost every frame, and pays this set-up each time).
    """

    __slots__ = ("bounds", "counts", "depth", "nodes", "normals", "order", "patches", "positions", "starts",
                 "stiffness", "tangential", "terms", "weighted")

    def __init__(self, mesh: SkinMesh, deformed: np.ndarray, force_model: ForceModel,
                 table: np.ndarray) -> None:
        nodes, counts = group_patches(mesh, deformed)
        nodes.setflags(write=False)  # shared by the contacts of every frame that reuses this split
        self.nodes = nodes
        self.counts: np.ndarray | float
        if len(counts) == 1:  # one patch (the common case): no reordering, no bounds to compute
            self.order = None
            self.starts = _FIRST
            self.counts = float(len(nodes))
            self.bounds = [(0, len(nodes))]
            self.patches = [nodes]
        else:
            # where each of ``nodes`` sits in the deformed set
            self.order = np.searchsorted(deformed, nodes)
            ends = np.cumsum(counts)
            self.starts = ends - counts
            self.counts = counts[:, None].astype(np.float64)
            self.bounds = list(zip(self.starts.tolist(), ends.tolist(), strict=True))
            self.patches = [nodes[a:b] for a, b in self.bounds]
        rows = table[nodes]
        self.positions, self.normals = rows[:, :4], rows[:, 4:]
        # the Winkler force is a product with the patch's spring constants: gathered once here
        # (contiguous: a strided vector takes another BLAS path, whose last bit may differ)
        self.stiffness: list[np.ndarray] | None = None
        if isinstance(force_model, WinklerForceModel):
            k = force_model.node_stiffness[nodes]
            self.stiffness = [k[a:b] for a, b in self.bounds]
        self.terms = np.empty((len(nodes), 8))
        self.weighted, self.tangential, self.depth = self.terms[:, :4], self.terms[:, 4:7], self.terms[:, 7]


def _contacts(p: _Patches, norms: np.ndarray, displacement: np.ndarray, force_model: ForceModel,
              min_nodes: int, peak: float | None = None) -> list[Contact]:
    """Every statistic of every patch from one ``reduceat`` over the nodes grouped by patch: a frame
    costs the same few array operations whether it has one contact or ten. ``peak``: the largest
    of ``norms`` if the caller has it (one patch then needs no max of its own)."""
    w = norms if p.order is None else norms[p.order]
    d = displacement[p.nodes]
    n = p.normals
    normal = np.einsum("ij,ij->i", d, n)
    np.multiply(w[:, None], p.positions, out=p.weighted)
    np.multiply(normal[:, None], n, out=p.tangential)
    np.subtract(d, p.tangential, out=p.tangential)
    np.abs(normal, out=p.depth)
    sums = np.add.reduceat(p.terms, p.starts)
    sums[:, 1:4] /= sums[:, :1]  # location: intensity-weighted mean
    sums[:, 4:] /= p.counts  # shear and depth: plain means
    rows = sums.tolist()
    if len(rows) == 1:
        ranked: list[int] | tuple[int] = (0,)
        peaks = [float(w.max()) if peak is None else peak]
    else:  # the largest contact first; ties keep patch order, as argsort(-total, kind="stable")
        ranked = sorted(range(len(rows)), key=lambda c: -rows[c][0])
        peaks = np.maximum.reduceat(w, p.starts).tolist()
    contacts = []
    for c in ranked:
        patch = p.patches[c]
        if len(patch) < min_nodes:
            continue
        if p.stiffness is None:
            force = force_model.force(patch, displacement)
        else:
            a, b = p.bounds[c]
            force = p.stiffness[c] @ (d if len(rows) == 1 else d[a:b])
        row = sums[c]
        contacts.append(Contact(patch, row[1:4], force, rows[c][0], peaks[c], row[4:7], rows[c][7]))
    return contacts


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
    return _contacts(_Patches(mesh, deformed, force_model, _node_table(mesh)), intensity[deformed],
                     displacement, force_model, min_nodes)


class ContactFinder:
    """``find_contacts`` over one device's frame sequence, given the deformed nodes' norms only.

    A held press deforms the same nodes frame after frame (about 9 frames in 10
    of the hub benchmark's moving press), so the split into patches and the
    per-node gathers it allows are kept for the last deformed set and reused
    while it stays the same: only the displacement-dependent statistics are
    computed again.
    """

    def __init__(self, mesh: SkinMesh, force_model: ForceModel, min_nodes: int = 1) -> None:
        self.mesh, self.force_model, self.min_nodes = mesh, force_model, min_nodes
        self._table = _node_table(mesh)
        self._key = b""
        self._patches: _Patches | None = None

    def find(self, deformed: np.ndarray, norms: np.ndarray, displacement: np.ndarray,
             peak: float | None = None) -> list[Contact]:
        """Contacts of ``deformed`` (ascending, not empty), whose displacement norms are ``norms``
        (``peak``: their largest, if known)."""
        key = deformed.tobytes()
        p = self._patches
        if p is None or key != self._key:
            p = self._patches = _Patches(self.mesh, deformed, self.force_model, self._table)
            self._key = key
        return _contacts(p, norms, displacement, self.force_model, self.min_nodes, peak)
