"""Contacts: the deformed nodes split into one patch per peak, each with its location and force."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .mesh import SkinMesh
from .segmentation import MeshGraph, Watershed, count_peaks

__all__ = ["Contact", "ContactFinder", "ForceModel", "WinklerForceModel", "find_contacts", "group_patches"]

# Above this many deformed nodes SciPy's compiled search beats the Python walk (its fixed cost,
# ~0.1 ms of sparse-matrix set-up, is paid back); below it the walk is 1.4-20x faster.
# Measured by `wott-hub bench processing` (docs/benchmarks.md, "Finding contact patches").
WALK_MAX_NODES = 400


_UNSET = (0.0, 0.0, 0.0)  # ``Contact.xyz`` not given: taken from ``location``


class ForceModel(Protocol):
    """Anything that turns a patch's displacements into the force on it (N, into the skin)."""

    def force(self, nodes: np.ndarray, displacement: np.ndarray) -> np.ndarray: ...


@dataclass(slots=True, eq=False)
class Contact:
    """One contact: its nodes, where it is and the force the skin feels there.

    ``base`` is the level its peak rises from (ε, or the valley to a higher
    neighbouring peak): the peak's prominence is ``peak - base``. ``id`` names
    the finger across frames (``tracking.ContactTracker``; 0 until tracked).
    Read-only once made (a frame's contacts are shared by its records); not
    frozen because a frozen dataclass takes 1.5 µs to build, a plain one 0.2,
    and every frame builds one per contact.
    """

    nodes: np.ndarray  # mesh node indices, ascending
    location: np.ndarray  # (3,) intensity-weighted mean rest position, mm
    force: np.ndarray  # (3,) N, pushing into the skin
    intensity: float  # sum of the nodes' displacement norms, mm
    peak: float  # largest displacement norm in the patch, mm
    shear: np.ndarray  # (3,) mean tangential displacement, mm
    depth: float  # mean normal displacement magnitude, mm
    area: float = 0.0  # the nodes' lumped area, mm²
    base: float = 0.0  # mm
    id: int = 0
    xyz: tuple[float, float, float] = _UNSET  # the location as Python floats (tracking, actions)
    radius: float = 0.0  # mm, measured by the driver (tactile.measured); 0: not measured

    def __post_init__(self) -> None:
        if self.xyz is _UNSET:
            x, y, z = self.location.tolist()
            self.xyz = (x, y, z)


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

    @classmethod
    def uniform(cls, mesh: SkinMesh, stiffness: float) -> WinklerForceModel:
        """Every node the same ``stiffness``: 1 when the node vectors are forces (a patch's force is
        their sum), 0 when they say nothing of force (a magnetic field, a taxel's counts)."""
        model = cls.__new__(cls)
        model.node_stiffness = np.full(mesh.n_nodes, float(stiffness))
        return model

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
    """Per node, what a patch's statistics gather, (1, position | normal | area): one gather for all."""
    return np.column_stack([np.ones(mesh.n_nodes), mesh.nodes, mesh.normals, mesh.node_areas])


class _Patches:
    """A deformed set split into patches, with what the statistics of any frame need of it.

    ``nodes`` are the set's nodes grouped by patch (``counts`` each), ``order``
    where each sits in the deformed set (None: in the set's own order, one
    patch). The per-node terms of the statistics are the columns of one
    (nodes x 12) array, weight x (1, position) | tangential displacement |
    normal depth | area | Winkler force k_i D_i, so one ``reduceat`` sums them
    all, for one patch or ten; a column sums exactly as the same values would
    alone, so the numbers are those of one reduction per statistic. The array is
    kept here and refilled each frame (the area column once). The weight is a
    node's norm above ``floor`` (ε): its norm times (1, position) less the
    constant ``floor_terms`` (floor x the patch's sums of (1, position), taken off the
    sums: one small subtraction a frame). The nodes' constants come from one gather of the
    finder's ``_node_table``; the spring constants (``stiffness``, a column) of
    the force model's, if it is a Winkler bed (another model is asked per patch).
    """

    __slots__ = ("bounds", "counts", "depth", "floor_terms", "force", "n", "nodes", "normals", "order",
                 "patches", "positions", "starts", "stiffness", "tangential", "terms", "weighted")

    def __init__(self, nodes: np.ndarray, counts: np.ndarray, order: np.ndarray | None,
                 force_model: ForceModel, table: np.ndarray, floor: float) -> None:
        nodes.setflags(write=False)  # shared by the contacts of every frame that reuses this split
        self.nodes = nodes
        self.counts: np.ndarray | float
        self.order = order
        self.n = counts.tolist()
        if len(counts) == 1:  # one patch (the common case): no bounds to compute
            self.starts = _FIRST
            self.counts = float(len(nodes))
            self.bounds = [(0, len(nodes))]
            self.patches = [nodes]
        else:
            ends = np.cumsum(counts)
            self.starts = ends - counts
            self.counts = counts[:, None].astype(np.float64)
            self.bounds = list(zip(self.starts.tolist(), ends.tolist(), strict=True))
            self.patches = [nodes[a:b] for a, b in self.bounds]
        rows = table[nodes]
        self.positions, self.normals = rows[:, :4], rows[:, 4:7]
        self.floor_terms = floor * np.add.reduceat(self.positions, self.starts) if floor else None
        self.stiffness: np.ndarray | None = None
        if isinstance(force_model, WinklerForceModel):
            self.stiffness = force_model.node_stiffness[nodes][:, None]
        self.terms = np.empty((len(nodes), 12))
        self.weighted, self.tangential, self.depth = self.terms[:, :4], self.terms[:, 4:7], self.terms[:, 7]
        self.force = self.terms[:, 9:12]
        self.terms[:, 8] = rows[:, 7]
        if self.stiffness is None:
            self.force[:] = 0.0


def _components(mesh: SkinMesh, deformed: np.ndarray, force_model: ForceModel, table: np.ndarray,
                floor: float) -> _Patches:
    """The connected patches of ``deformed`` (``group_patches``)."""
    nodes, counts = group_patches(mesh, deformed)
    order = None if len(counts) == 1 else np.searchsorted(deformed, nodes)
    return _Patches(nodes, counts, order, force_model, table, floor)


def _contacts(p: _Patches, norms: np.ndarray, displacement: np.ndarray, force_model: ForceModel,
              min_nodes: int, floor: float, peak: float | None = None, bases: list[float] | None = None
              ) -> list[Contact]:
    """Every statistic of every patch from one ``reduceat`` over the nodes grouped by patch: a frame
    costs the same few array operations whether it has one contact or ten. ``peak``: the largest
    of ``norms`` if the caller has it (one patch then needs no max of its own); ``bases``: each
    patch's base (default ``floor``).

    The location weighs each node by how far its norm rises above ``floor`` (ε), not by the
    whole norm: a node crossing ε then moves the location continuously instead of by a jump
    (a coarse mesh's contact would lurch as a press ramps in or out, a false speed). A patch
    of nodes that belong to no cell (a mesh with a hole in its cells) has no area: it is
    reported in the packet, but no skin there carries a force, so it is no contact.
    """
    w = norms if p.order is None else norms[p.order]
    d = displacement[p.nodes]
    n = p.normals
    normal = np.einsum("ij,ij->i", d, n)
    np.multiply(w[:, None], p.positions, out=p.weighted)
    np.multiply(normal[:, None], n, out=p.tangential)
    np.subtract(d, p.tangential, out=p.tangential)
    np.abs(normal, out=p.depth)
    if p.stiffness is not None:
        np.multiply(p.stiffness, d, out=p.force)
    sums = np.add.reduceat(p.terms, p.starts)
    if p.floor_terms is not None:  # the weights less ε: Σ (w - ε)(1, x) = Σ w (1, x) - ε Σ (1, x)
        sums[:, :4] -= p.floor_terms
    sums[:, 1:4] /= sums[:, :1]  # location: weighted mean
    sums[:, 4:8] /= p.counts  # shear and depth: plain means
    rows = sums.tolist()
    if len(rows) == 1:
        ranked: list[int] | tuple[int] = (0,)
        peaks = [float(w.max()) if peak is None else peak]
    else:  # the largest contact first; ties keep patch order, as argsort(-total, kind="stable")
        ranked = sorted(range(len(rows)), key=lambda c: -(rows[c][0] + floor * p.n[c]))
        peaks = np.maximum.reduceat(w, p.starts).tolist()
    contacts = []
    for c in ranked:
        patch = p.patches[c]
        if len(patch) < min_nodes or rows[c][8] <= 0.0:  # too small, or nodes in no cell: no skin, no contact
            continue
        row = sums[c]
        force = row[9:12] if p.stiffness is not None else force_model.force(patch, displacement)
        r = rows[c]
        contacts.append(Contact(patch, row[1:4], force, r[0] + floor * p.n[c], peaks[c], row[4:7], r[7], r[8],
                                floor if bases is None else bases[c], 0, (r[1], r[2], r[3])))
    return contacts


def find_contacts(
    mesh: SkinMesh,
    deformed: np.ndarray,
    intensity: np.ndarray,
    displacement: np.ndarray,
    force_model: ForceModel,
    min_nodes: int = 1,
) -> list[Contact]:
    """Split the deformed nodes into connected patches on the mesh graph (no split by peak).

    ``deformed`` holds node indices (ascending), ``intensity`` the displacement
    norm of every node. Patches smaller than ``min_nodes`` are dropped as noise.
    """
    if deformed.size == 0:
        return []
    return _contacts(_components(mesh, deformed, force_model, _node_table(mesh), 0.0), intensity[deformed],
                     displacement, force_model, min_nodes, 0.0)


class _Split:
    """What is kept of one deformed set: its connected patches, its neighbourhood and watershed when
    first needed, and its last split by peak (reused while the watershed groups its nodes the same way)."""

    __slots__ = ("components", "n_components", "nbh", "peaks", "peaks_key", "watershed")

    def __init__(self, components: _Patches) -> None:
        self.components, self.n_components = components, len(components.patches)
        self.nbh: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.watershed: Watershed | None = None
        self.peaks: _Patches | None = None
        self.peaks_key = b""


class ContactFinder:
    """One contact per peak of each frame's deformed nodes, over one device's frame sequence.

    ``segmentation`` is "peaks" (``segmentation.Watershed``: two fingers whose
    valley stays above ε are two contacts) or "components" (each connected
    patch one contact, whatever its peaks: cheaper, and what the hub did before
    issue 31). ``floor``: ε, the level locations are weighed from. A held press
    deforms the same nodes frame after frame (about 9 frames in 10 of the hub
    benchmark's moving press), so the split into patches, the gathers it allows
    and the set's neighbourhood are kept for the last deformed set and reused
    while it stays the same. A patch with a single maximum (a smooth press) is
    one contact without a watershed.
    """

    def __init__(self, mesh: SkinMesh, force_model: ForceModel, min_nodes: int = 1,
                 segmentation: str = "peaks", floor: float = 0.0) -> None:
        if segmentation not in ("peaks", "components"):
            raise ValueError(f"segmentation must be 'peaks' or 'components', got {segmentation!r}")
        self.mesh, self.force_model, self.min_nodes, self.floor = mesh, force_model, min_nodes, floor
        self.by_peaks = segmentation == "peaks"
        self._table = _node_table(mesh)
        self._graph: MeshGraph | None = None
        self._key = b""
        self._split: _Split | None = None

    def find(self, deformed: np.ndarray, norms: np.ndarray, displacement: np.ndarray,
             peak: float | None = None, field: np.ndarray | None = None, merge_mm: float = 0.0,
             merge_ratio: float = 0.0) -> list[Contact]:
        """Contacts of ``deformed`` (ascending, not empty), whose displacement norms are ``norms``
        (``peak``: their largest, if known). ``field``: every node's norm followed by -inf, if the
        caller has it (``count_peaks``; a clamped node's value there can only hide a peak beside it,
        which leaves its patch whole, as before issue 31). ``merge_mm`` and ``merge_ratio``: the
        watershed's (``segmentation.Watershed``); each contact's ``base`` is at least ``floor``."""
        key = deformed.tobytes()
        split = self._split
        if split is None or key != self._key:
            split = self._split = _Split(_components(self.mesh, deformed, self.force_model, self._table,
                                                     self.floor))
            self._key = key
        floor = self.floor
        if self.by_peaks:
            graph = self._graph
            if graph is None:
                graph = self._graph = MeshGraph(self.mesh)
            nbh = split.nbh
            if nbh is None:
                nbh = split.nbh = graph.neighbours_of(deformed)
            rows, flat, starts = nbh
            if field is None:
                field = np.full(self.mesh.n_nodes + 1, -np.inf)
                field[deformed] = norms
            if count_peaks(flat, starts, field, norms) > split.n_components:  # else one peak a patch
                ws = split.watershed
                if ws is None:
                    ws = split.watershed = Watershed(graph, deformed, rows)
                seg = ws.split(norms, floor, merge_mm, merge_ratio)
                if len(seg.counts) > split.n_components:  # else the extra maxima merged: the patches again
                    p = split.peaks
                    if p is None or seg.key != split.peaks_key:
                        p = split.peaks = _Patches(deformed[seg.order], seg.counts, seg.order,
                                                   self.force_model, self._table, floor)
                        split.peaks_key = seg.key
                    return _contacts(p, norms, displacement, self.force_model, self.min_nodes, floor, None,
                                     seg.base)
        return _contacts(split.components, norms, displacement, self.force_model, self.min_nodes, floor, peak)
