"""Contact probes: the points of the skin surface an indenter can push on.

A mesh node is a probe, but a device mesh is often coarser than a fingertip
(the TacLink barrel's edges are ~12 mm long, a finger's radius ~6 mm): an
indenter pressed between nodes would touch nothing. So every triangle also
carries a grid of probes, s per edge, each a fixed barycentric combination of
the triangle's three nodes. Pushing a probe pushes the face, i.e. those nodes
in proportion to its weights; the skin's resolution stays the mesh's, but no
indenter can slip through it. Quads are sampled as their two 0-2 triangles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..mesh import SkinMesh

__all__ = ["ProbeSet", "build_probes"]


@dataclass(frozen=True, slots=True, eq=False)
class ProbeSet:
    nodes: np.ndarray  # (P, 3) mesh node indices (repeated when fewer than three)
    weights: np.ndarray  # (P, 3) barycentric weights, rows sum to 1
    rest: np.ndarray  # (P, 3) rest position, mm
    normals: np.ndarray  # (P, 3) interpolated outward unit normal (zero where undefined)

    def __len__(self) -> int:
        return len(self.nodes)


def build_probes(mesh: SkinMesh, spacing_mm: float) -> ProbeSet:
    """Nodes, then s − 1 points inside each edge, then the interior grid of each triangle."""
    tris = mesh.triangles()
    p = mesh.nodes
    n = mesh.n_nodes
    node_rows = np.arange(n)
    nodes = [np.stack([node_rows] * 3, axis=1)]
    weights = [np.tile([1.0, 0.0, 0.0], (n, 1))]
    if len(tris):
        pairs = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
        edges = np.unique(pairs, axis=0)
        lengths = np.linalg.norm(p[edges[:, 1]] - p[edges[:, 0]], axis=1)
        median = float(np.median(lengths[lengths > 0])) if (lengths > 0).any() else 0.0
        s = int(min(12, max(1, math.ceil(median / spacing_mm)))) if median > 0 else 1
    else:
        s = 1
    if s > 1:
        t = np.arange(1, s) / s
        ne = len(edges)
        nodes.append(np.stack([np.repeat(edges[:, 0], s - 1), np.repeat(edges[:, 1], s - 1),
                               np.repeat(edges[:, 0], s - 1)], axis=1))
        weights.append(np.stack([np.tile(1 - t, ne), np.tile(t, ne), np.zeros(ne * (s - 1))], axis=1))
        bary = np.array([(i, j, s - i - j) for i in range(1, s) for j in range(1, s - i)], dtype=float) / s
        if len(bary):
            nt, nb = len(tris), len(bary)
            nodes.append(np.repeat(tris, nb, axis=0))
            weights.append(np.tile(bary, (nt, 1)))
    nodes_a = np.concatenate(nodes).astype(np.int64)
    weights_a = np.concatenate(weights)
    rest = np.einsum("pk,pkc->pc", weights_a, p[nodes_a])
    nrm = np.einsum("pk,pkc->pc", weights_a, mesh.normals[nodes_a])
    norm = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.divide(nrm, norm, out=np.zeros_like(nrm), where=norm > 1e-12)
    return ProbeSet(nodes_a, weights_a, rest, nrm)
