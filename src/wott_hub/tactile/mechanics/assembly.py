"""Element stiffnesses of the skin, assembled into sparse 3N x 3N matrices.

Three kinds of Kelvin-Voigt element, each a spring (this module) with a dashpot
of τ times the same matrix (the model adds C = τK):

* **Edge springs** (membrane). Axial stiffness from Van Gelder's rule for
  triangulated spring meshes, k_e = E h Σ_t A_t / L_e² over the triangles t
  sharing the edge: on an equilateral lattice it reproduces a membrane of
  stiffness E h with Poisson's ratio 1/3 (a spring network cannot do 1/2).
  Quads are split both ways, each split counting half, so a grid has no
  preferred diagonal.
* **Shear layer on the edges** (Pasternak/Vlasov). A tension τ_m (N/mm) acting
  across the edge gives it a transverse stiffness τ_m w_e, with w_e the
  cotangent weight of the edge; on a flat mesh this is the discrete
  −τ_m ∇² of a membrane. τ_m = G h / 3 (Vlasov's layer with a linear decay
  through the thickness, G = E/3 for an incompressible rubber) couples a node
  to its neighbours out of plane; an inflated skin adds its pretension.
* **Foundation** (Winkler) at every node: E A_i / h along the node normal and
  G A_i / h across it — the through-thickness stiffness of the skin layer,
  the same bed the processing's ``WinklerForceModel`` assumes.

Degenerate geometry never produces NaN/Inf: zero-length edges become an
isotropic spring of the median edge stiffness (coincident nodes move
together), stiffnesses are capped at ``STIFFNESS_CAP`` times the median and
cotangent weights are clamped to [0, ``COT_CAP``].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..mesh import SkinMesh

__all__ = [
    "COT_CAP", "STIFFNESS_CAP", "EdgeSet", "assemble_blocks", "edge_blocks", "edge_set", "foundation_blocks",
]

STIFFNESS_CAP = 1e4  # largest edge stiffness, in median edge stiffnesses
COT_CAP = 1e3  # largest cotangent (a sliver with an angle under ~0.06°)
ZERO_LENGTH = 1e-9  # an edge shorter than this many median lengths has no direction


@dataclass(frozen=True, slots=True)
class EdgeSet:
    """The mechanical edges of a mesh: node pairs, rest vectors and per-edge weights."""

    pairs: np.ndarray  # (E, 2) node indices, smaller first
    vectors: np.ndarray  # (E, 3) rest vector from pairs[:, 0] to pairs[:, 1], mm
    lengths: np.ndarray  # (E,) mm
    area_over_l2: np.ndarray  # (E,) Σ_t A_t / L², dimensionless (Van Gelder)
    cot_weight: np.ndarray  # (E,) (cot α + cot β) / 2, clamped


def _triangles(mesh: SkinMesh) -> tuple[np.ndarray, np.ndarray]:
    c = mesh.cells
    if c.shape[1] == 3:
        return c, np.ones(len(c))
    tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]], c[:, [0, 1, 3]], c[:, [1, 2, 3]]])
    return tris, np.full(len(tris), 0.5)


def edge_set(mesh: SkinMesh) -> EdgeSet:
    """Edges of the (both-ways) triangulated mesh with Van Gelder and cotangent weights."""
    p = mesh.nodes
    tris, w = _triangles(mesh)
    if len(tris) == 0:
        z = np.zeros(0)
        return EdgeSet(np.zeros((0, 2), np.int64), np.zeros((0, 3)), z, z, z)
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    cross_len = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    area = 0.5 * cross_len
    pairs, vg, cot = [], [], []
    # edge (j, k) is opposite vertex i; the cotangent of the angle at i weights it
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        pi, pj, pk = p[tris[:, i]], p[tris[:, j]], p[tris[:, k]]
        e1, e2 = pj - pi, pk - pi
        dot = np.einsum("ij,ij->i", e1, e2)
        scale = np.einsum("ij,ij->i", e1, e1) * np.einsum("ij,ij->i", e2, e2)
        floor = np.sqrt(scale) / COT_CAP  # |e1 x e2| below this would exceed COT_CAP
        cot_i = np.where(scale > 0, dot / np.maximum(cross_len, np.maximum(floor, 1e-300)), 0.0)
        l2 = np.einsum("ij,ij->i", pk - pj, pk - pj)
        pairs.append(np.sort(tris[:, [j, k]], axis=1))
        vg.append(np.divide(w * area, l2, out=np.zeros_like(l2), where=l2 > 0))
        cot.append(w * np.clip(cot_i, -COT_CAP, COT_CAP) / 2.0)
    allpairs = np.concatenate(pairs)
    uniq, inv = np.unique(allpairs, axis=0, return_inverse=True)
    inv = inv.ravel()
    vg_e = np.bincount(inv, weights=np.concatenate(vg), minlength=len(uniq))
    cot_e = np.clip(np.bincount(inv, weights=np.concatenate(cot), minlength=len(uniq)), 0.0, COT_CAP)
    vec = p[uniq[:, 1]] - p[uniq[:, 0]]
    return EdgeSet(uniq, vec, np.linalg.norm(vec, axis=1), vg_e, cot_e)


def edge_blocks(edges: EdgeSet, membrane_n_per_mm: float, tension_n_per_mm: float) -> np.ndarray:
    """(E, 3, 3) stiffness block of each edge: k n nᵀ + t (I − n nᵀ)."""
    n_e = len(edges.lengths)
    if n_e == 0:
        return np.zeros((0, 3, 3))
    k = membrane_n_per_mm * edges.area_over_l2
    t = tension_n_per_mm * edges.cot_weight
    median_l = float(np.median(edges.lengths[edges.lengths > 0])) if (edges.lengths > 0).any() else 1.0
    zero = edges.lengths <= ZERO_LENGTH * median_l
    positive = k[~zero & (k > 0)]
    k_med = float(np.median(positive)) if positive.size else max(membrane_n_per_mm, 1e-12)
    k = np.minimum(k, STIFFNESS_CAP * k_med)
    if (t > 0).any():
        t = np.minimum(t, STIFFNESS_CAP * float(np.median(t[t > 0])))
    n = np.zeros((n_e, 3))
    np.divide(edges.vectors, edges.lengths[:, None], out=n, where=~zero[:, None])
    nn = n[:, :, None] * n[:, None, :]
    eye = np.broadcast_to(np.eye(3), (n_e, 3, 3))
    blocks = k[:, None, None] * nn + t[:, None, None] * (eye - nn)
    blocks[zero] = k_med * np.eye(3)  # coincident nodes: glue them together
    return blocks


def foundation_blocks(mesh: SkinMesh, normal_per_area: float, tangent_per_area: float) -> np.ndarray:
    """(N, 3, 3) Winkler block of each node: stiffness per area times the node's area."""
    n = mesh.normals
    a = mesh.node_areas
    nn = n[:, :, None] * n[:, None, :]
    eye = np.broadcast_to(np.eye(3), (len(a), 3, 3))
    blocks: np.ndarray = a[:, None, None] * (normal_per_area * nn + tangent_per_area * (eye - nn))
    return blocks


def assemble_blocks(
    n_nodes: int, pairs: np.ndarray, edge_k: np.ndarray, node_k: np.ndarray | None = None
) -> sp.csr_matrix:
    """Global 3N x 3N matrix from two-node blocks [[B, −B], [−B, B]] and one-node blocks."""
    i, j = pairs[:, 0], pairs[:, 1]
    r3 = np.arange(3)
    rows, cols, data = [], [], []

    def add(a: np.ndarray, b: np.ndarray, blk: np.ndarray, sign: float) -> None:
        rr = (3 * a[:, None, None] + r3[None, :, None]).repeat(3, axis=2)
        cc = (3 * b[:, None, None] + r3[None, None, :]).repeat(3, axis=1)
        rows.append(rr.ravel())
        cols.append(cc.ravel())
        data.append(sign * blk.ravel())

    add(i, i, edge_k, 1.0)
    add(j, j, edge_k, 1.0)
    add(i, j, edge_k, -1.0)
    add(j, i, edge_k, -1.0)
    if node_k is not None:
        idx = np.arange(n_nodes)
        add(idx, idx, node_k, 1.0)
    m = sp.coo_matrix(
        (np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n_nodes, 3 * n_nodes)
    ).tocsr()
    m.sum_duplicates()
    return m
