"""Skin meshes: the geometry every tactile computation is done on.

A skin is a surface mesh (triangles or quads) whose nodes are the points the
device can measure (markers, taxels) or estimate (FE nodes). Nodes near rigid
mounts are *clamped*: they never move, so processing and mechanics skip them.
All lengths are in millimetres in the device's ``sensorCoordinateFrame``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from wott_hub.errors import InvalidInput

if TYPE_CHECKING:  # SciPy is imported where a sparse matrix is needed: processing never needs one
    import scipy.sparse as sp

__all__ = [
    "MeshError",
    "SkinMesh",
    "barrel",
    "cylinder",
    "flat_pad",
    "load_taclink_barrel",
    "mesh_spacing",
    "taclink_barrel",
]

TACLINK_DATA = Path(__file__).parent / "data" / "taclink"


class MeshError(InvalidInput):
    """The mesh description is impossible (bad shapes, indices out of range, NaN...)."""


@dataclass(frozen=True, eq=False)
class SkinMesh:
    """An immutable surface mesh with the derived topology processing needs.

    ``cells`` is an (M, 3) array of triangles or an (M, 4) array of quads, each
    cell listing its nodes counter-clockwise seen from outside the skin so that
    normals point away from the sensor's interior. ``free`` marks the nodes
    that may move; the others are clamped.
    """

    nodes: np.ndarray
    cells: np.ndarray
    free: np.ndarray
    name: str = "skin"

    def __post_init__(self) -> None:
        nodes = np.ascontiguousarray(self.nodes, dtype=np.float64)
        cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        free = np.ascontiguousarray(self.free, dtype=bool)
        if nodes.ndim != 2 or nodes.shape[1] != 3 or len(nodes) == 0:
            raise MeshError(f"nodes must be an (N, 3) array with N > 0, got shape {nodes.shape}")
        if not np.isfinite(nodes).all():
            raise MeshError("nodes contain NaN or Inf coordinates")
        if cells.ndim != 2 or cells.shape[1] not in (3, 4):
            raise MeshError(f"cells must be (M, 3) triangles or (M, 4) quads, got {cells.shape}")
        if cells.size and (cells.min() < 0 or cells.max() >= len(nodes)):
            raise MeshError(f"cell indices must lie in [0, {len(nodes) - 1}]")
        if cells.size:
            srt = np.sort(cells, axis=1)
            bad = np.flatnonzero((srt[:, 1:] == srt[:, :-1]).any(axis=1))
            if bad.size:
                raise MeshError(f"cell {int(bad[0])} repeats a node: {cells[bad[0]].tolist()}")
        if free.shape != (len(nodes),):
            raise MeshError(f"free must be a boolean mask of length {len(nodes)}, got {free.shape}")
        for attr, value in (("nodes", nodes), ("cells", cells), ("free", free)):
            value.setflags(write=False)
            object.__setattr__(self, attr, value)

    # -- sizes ---------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_cells(self) -> int:
        return len(self.cells)

    @cached_property
    def free_indices(self) -> np.ndarray:
        return np.flatnonzero(self.free)

    @cached_property
    def clamped_indices(self) -> np.ndarray:
        return np.flatnonzero(~self.free)

    # -- topology ------------------------------------------------------------
    @cached_property
    def edges(self) -> np.ndarray:
        """Unique undirected edges (E, 2), each with the smaller index first.

        Quads contribute their four sides only (not diagonals), so a quad mesh's
        graph is the marker/taxel grid a user would draw.
        """
        k = self.cells.shape[1]
        pairs = np.concatenate([self.cells[:, [i, (i + 1) % k]] for i in range(k)])
        pairs.sort(axis=1)
        return np.unique(pairs, axis=0)

    @cached_property
    def neighbour_csr(self) -> tuple[np.ndarray, np.ndarray]:
        """(indptr, indices) of every node's neighbours, ascending: the adjacency without SciPy."""
        e = self.edges
        rows = np.concatenate([e[:, 0], e[:, 1]])
        cols = np.concatenate([e[:, 1], e[:, 0]])
        order = np.lexsort((cols, rows))
        indptr = np.zeros(self.n_nodes + 1, dtype=np.int64)
        np.cumsum(np.bincount(rows, minlength=self.n_nodes), out=indptr[1:])
        return indptr, cols[order]

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """Symmetric node adjacency (N x N, CSR, ones on edges)."""
        import scipy.sparse as sp

        indptr, indices = self.neighbour_csr
        n = self.n_nodes
        return sp.csr_matrix((np.ones(len(indices), dtype=np.int8), indices, indptr), shape=(n, n))

    @cached_property
    def neighbour_lists(self) -> tuple[tuple[int, ...], ...]:
        """Each node's neighbours as Python ints: a walk over a few dozen nodes (a contact patch)
        is several times faster on tuples than on arrays or a sparse matrix."""
        indptr, indices = self.neighbour_csr
        flat = indices.tolist()
        return tuple(tuple(flat[a:b]) for a, b in zip(indptr[:-1].tolist(), indptr[1:].tolist(), strict=True))

    def neighbours(self, node: int) -> np.ndarray:
        indptr, indices = self.neighbour_csr
        return indices[indptr[node] : indptr[node + 1]]

    # -- geometry ------------------------------------------------------------
    def triangles(self) -> np.ndarray:
        """The cells as triangles (quads split along their 0-2 diagonal)."""
        if self.cells.shape[1] == 3:
            return self.cells
        c = self.cells
        return np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])

    @cached_property
    def cell_normals(self) -> np.ndarray:
        """Unit normal per cell from its winding (zero for degenerate cells)."""
        p = self.nodes
        c = self.cells
        if c.shape[1] == 3:
            n = np.cross(p[c[:, 1]] - p[c[:, 0]], p[c[:, 2]] - p[c[:, 0]])
        else:  # quad: cross product of the diagonals is robust to non-planarity
            n = np.cross(p[c[:, 2]] - p[c[:, 0]], p[c[:, 3]] - p[c[:, 1]])
        return _normalise(n)

    @cached_property
    def cell_areas(self) -> np.ndarray:
        p = self.nodes
        t = self.triangles()
        a = 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]), axis=1)
        if self.cells.shape[1] == 4:
            a = a[: self.n_cells] + a[self.n_cells :]
        areas: np.ndarray = a
        return areas

    @cached_property
    def node_areas(self) -> np.ndarray:
        """Lumped area per node (each cell's area shared equally by its nodes), mm²."""
        k = self.cells.shape[1]
        return np.bincount(
            self.cells.ravel(), weights=np.repeat(self.cell_areas / k, k), minlength=self.n_nodes
        )

    @cached_property
    def normals(self) -> np.ndarray:
        """Area-weighted unit normal per node; zero for nodes in no cell."""
        k = self.cells.shape[1]
        w = (self.cell_normals * self.cell_areas[:, None]).repeat(k, axis=0)
        acc = np.zeros_like(self.nodes)
        np.add.at(acc, self.cells.ravel(), w)
        return _normalise(acc)

    def with_free(self, free: np.ndarray) -> SkinMesh:
        return SkinMesh(self.nodes, self.cells, free, self.name)


def mesh_spacing(mesh: SkinMesh) -> float:
    """The median edge length (mm): the scale of what the mesh can resolve."""
    e = mesh.edges
    if not len(e):
        return 1.0
    return float(np.median(np.linalg.norm(mesh.nodes[e[:, 0]] - mesh.nodes[e[:, 1]], axis=1)))


def _normalise(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    out = np.zeros_like(v)
    np.divide(v, norm, out=out, where=norm > 1e-12)
    return out


def orient_outward(nodes: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Re-wind cells so neighbours agree and normals point away from the centroid.

    Mesh files do not promise a consistent winding; a breadth-first walk over
    shared edges flips each cell to match its neighbour, then the whole surface
    is flipped if it faces inward on average.
    """
    cells = cells.copy()
    m, k = cells.shape
    edge_owner: dict[tuple[int, int], list[int]] = {}
    for ci, cell in enumerate(cells):
        for i in range(k):
            a, b = int(cell[i]), int(cell[(i + 1) % k])
            edge_owner.setdefault((min(a, b), max(a, b)), []).append(ci)
    seen = np.zeros(m, dtype=bool)
    for start in range(m):
        if seen[start]:
            continue
        seen[start] = True
        stack = [start]
        while stack:
            ci = stack.pop()
            cell = cells[ci]
            for i in range(k):
                a, b = int(cell[i]), int(cell[(i + 1) % k])
                for cj in edge_owner[(min(a, b), max(a, b))]:
                    if seen[cj]:
                        continue
                    other = list(cells[cj])
                    j = other.index(a)
                    if other[(j + 1) % k] == b:  # same direction: inconsistent winding
                        cells[cj] = cells[cj][::-1]
                    seen[cj] = True
                    stack.append(cj)
    probe = SkinMesh(nodes, cells, np.ones(len(nodes), bool))
    centre = nodes.mean(axis=0)
    facing = np.einsum("ij,ij->", probe.cell_normals * probe.cell_areas[:, None],
                       nodes[cells].mean(axis=1) - centre)
    if facing < 0:
        cells = cells[:, ::-1].copy()
    return cells


# -- generators ----------------------------------------------------------------
def flat_pad(
    rows: int,
    cols: int,
    *,
    pitch_mm: float = 2.0,
    clamp_border: bool = True,
    name: str = "flat-pad",
) -> SkinMesh:
    """A rows x cols grid of nodes in the z = 0 plane joined by quads, normal +z.

    Node (r, c) has index ``r * cols + c`` and sits at x = c * pitch, y = r * pitch,
    so the marker grid of a vision pad or the cell grid of a taxel array maps
    onto it one to one. The outer ring is clamped by default (the gel's frame).
    """
    if rows < 2 or cols < 2:
        raise MeshError(f"a pad needs at least 2 x 2 nodes, got {rows} x {cols}")
    if not pitch_mm > 0:
        raise MeshError(f"pitch must be positive, got {pitch_mm}")
    r, c = np.mgrid[0:rows, 0:cols]
    nodes = np.column_stack([c.ravel() * pitch_mm, r.ravel() * pitch_mm, np.zeros(rows * cols)])
    idx = np.arange(rows * cols).reshape(rows, cols)
    cells = np.column_stack(
        [idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()]
    )
    free = np.ones((rows, cols), dtype=bool)
    if clamp_border:
        free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = False
    return SkinMesh(nodes, cells, free.ravel(), name)


def barrel(
    base_radius_mm: float,
    middle_radius_mm: float,
    height_mm: float,
    *,
    rings: int = 24,
    rays: int = 32,
    clamp_margin_mm: float = 20.0,
    name: str = "barrel",
) -> SkinMesh:
    """A surface of revolution about z, radius parabolic from base to middle.

    Rings are evenly spaced in z from 0 to height; nodes closer than
    ``clamp_margin_mm`` to either rim are clamped (the camera housings).
    """
    if rings < 2 or rays < 3:
        raise MeshError(f"need >= 2 rings and >= 3 rays, got {rings} x {rays}")
    if min(base_radius_mm, middle_radius_mm, height_mm) <= 0:
        raise MeshError("radii and height must be positive")
    z = np.linspace(0.0, height_mm, rings)
    s = 2.0 * z / height_mm - 1.0  # -1 at the base, 0 in the middle, +1 at the top
    radius = middle_radius_mm + (base_radius_mm - middle_radius_mm) * s**2
    theta = np.linspace(0.0, 2 * np.pi, rays, endpoint=False)
    zz, tt = np.meshgrid(z, theta, indexing="ij")
    rr = np.broadcast_to(radius[:, None], zz.shape)
    nodes = np.column_stack([(rr * np.cos(tt)).ravel(), (rr * np.sin(tt)).ravel(), zz.ravel()])
    idx = np.arange(rings * rays).reshape(rings, rays)
    nxt = np.roll(idx, -1, axis=1)
    a, b, c, d = idx[:-1], nxt[:-1], nxt[1:], idx[1:]
    cells = np.concatenate(
        [np.column_stack([a.ravel(), b.ravel(), c.ravel()]),
         np.column_stack([a.ravel(), c.ravel(), d.ravel()])]
    )
    free = (zz.ravel() >= clamp_margin_mm) & (zz.ravel() <= height_mm - clamp_margin_mm)
    return SkinMesh(nodes, orient_outward(nodes, cells), free, name)


def cylinder(radius_mm: float, height_mm: float, **kwargs: Any) -> SkinMesh:
    """A straight cylinder: a barrel whose middle radius equals its base radius."""
    kwargs.setdefault("name", "cylinder")
    return barrel(radius_mm, radius_mm, height_mm, **kwargs)


def load_taclink_barrel(vtk_path: Path, node_idx_csv: Path, label_idx_csv: Path) -> SkinMesh:
    """Read the TacLink barrel: the surface from VTK, the free nodes from the FE ids.

    ``node_idx.csv`` gives each surface node's id in the volumetric FE model and
    ``label_idx.csv`` the ids of the free (unclamped) ones, so matching the two
    sets yields the free mask without relying on node order or file line numbers.
    """
    import meshio  # only needed for files; generators do not pay for the import

    m = meshio.read(vtk_path)
    tri = [block.data for block in m.cells if block.type == "triangle"]
    if not tri:
        raise MeshError(f"{vtk_path} has no triangle cells")
    cells = np.concatenate(tri)
    fe_ids = _read_id_column(node_idx_csv)
    free_ids = _read_id_column(label_idx_csv)
    if len(fe_ids) != len(m.points):
        raise MeshError(f"{node_idx_csv} lists {len(fe_ids)} ids for {len(m.points)} nodes")
    free = np.isin(fe_ids, free_ids)
    if free.sum() != len(np.unique(free_ids)):
        raise MeshError("some free-node ids in label_idx are not surface nodes")
    return SkinMesh(m.points, orient_outward(m.points, cells), free, "taclink-barrel")


def _read_id_column(path: Path) -> np.ndarray:
    """First column of an id CSV with a header line (label_idx has trailing empty columns)."""
    return np.loadtxt(path, delimiter=",", skiprows=1, usecols=0, dtype=np.int64, ndmin=1)


def taclink_barrel() -> SkinMesh:
    """The TacLink barrel shipped with the package: the MIT-licensed SimTacLS mesh.

    Shipped as the arrays ``load_taclink_barrel`` reads from its ``barrel_skin.vtk``,
    ``node_idx.csv`` and ``label_idx.csv`` (NumPy's .npz), not as those files: a hub that
    opens a barrel then does not import meshio (0.1-0.3 s of start-up before the TDs
    are served, on this 2-core machine). tests/tactile/test_mesh.py checks it against the
    original files (../shared/data).
    """
    with np.load(TACLINK_DATA / "barrel_skin.npz") as arrays:
        return SkinMesh(arrays["nodes"], arrays["cells"], arrays["free"], "taclink-barrel")
