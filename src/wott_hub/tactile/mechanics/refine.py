"""Midpoint subdivision: a finer copy of a mesh that keeps the original nodes first.

A device's mesh is where it measures, not necessarily fine enough to compute
on: the TacLink barrel's 12 mm edges are twice a fingertip's radius, so a
press spreads over whole faces and comes out several times too stiff. Ground
truth is better computed on a subdivided copy and read back at the device's
nodes, which keep their indices 0..N−1 here.

Each level splits a triangle into four (edge midpoints) and a quad into four
(edge midpoints and centre); windings are kept. New nodes lie on the flat
faces (the surface is not re-curved) and are clamped only when every node
they come from is clamped.
"""

from __future__ import annotations

import numpy as np

from ..mesh import MeshError, SkinMesh

__all__ = ["subdivide"]


def subdivide(mesh: SkinMesh, levels: int = 1) -> SkinMesh:
    """The mesh subdivided ``levels`` times; ``result.nodes[:mesh.n_nodes]`` are the original nodes."""
    if levels < 0:
        raise MeshError(f"subdivision levels must be >= 0, got {levels}")
    for _ in range(levels):
        mesh = _once(mesh)
    return mesh


def _once(mesh: SkinMesh) -> SkinMesh:
    c = mesh.cells
    k = c.shape[1]
    n = mesh.n_nodes
    sides = np.stack([c[:, [i, (i + 1) % k]] for i in range(k)], axis=1)  # (M, k, 2)
    flat = np.sort(sides.reshape(-1, 2), axis=1)
    edges, inv = np.unique(flat, axis=0, return_inverse=True)
    mid = n + inv.reshape(len(c), k)  # index of each side's midpoint
    nodes = [mesh.nodes, 0.5 * (mesh.nodes[edges[:, 0]] + mesh.nodes[edges[:, 1]])]
    free = [mesh.free, mesh.free[edges[:, 0]] | mesh.free[edges[:, 1]]]
    if k == 3:
        a, b, cc = c[:, 0], c[:, 1], c[:, 2]
        ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
        cells = np.concatenate([
            np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1),
            np.stack([ca, bc, cc], 1), np.stack([ab, bc, ca], 1),
        ])
    else:
        centre = n + len(edges) + np.arange(len(c))
        nodes.append(mesh.nodes[c].mean(axis=1))
        free.append(mesh.free[c].any(axis=1))
        a, b, cc, d = c.T
        ab, bc, cd, da = mid.T
        cells = np.concatenate([
            np.stack([a, ab, centre, da], 1), np.stack([ab, b, bc, centre], 1),
            np.stack([centre, bc, cc, cd], 1), np.stack([da, centre, cd, d], 1),
        ])
    return SkinMesh(np.concatenate(nodes), cells, np.concatenate(free), mesh.name)
