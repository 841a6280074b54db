"""Contact segmentation: one contact per significant peak of the intensity field on the mesh graph.

Two fingers close together make one connected set of deformed nodes with two clear
peaks and a valley between them that may stay above ε; a camera estimate's noise makes
small extra maxima on a press's flank. So the deformed nodes are split by a watershed
with persistence, not by connectivity:

1. every node climbs to its highest neighbour (steepest ascent; ties broken by node
   order, so a plateau has one top) until it reaches a local maximum: its *basin*;
2. adjacent basins meet at a *saddle*, the highest of the lower ends of the edges
   between them; taken from the highest saddle down (a merge tree), two basins stay
   apart only if the valley is significantly below the lower peak: by more than
   ``merge_mm`` (the device's noise) and more than ``merge_ratio`` of that peak (its
   estimate's error grows with the deformation); otherwise the lower basin joins the
   other (elder rule: the union keeps the higher peak).

Each deformed node ends in exactly one segment. A segment's *base* is the highest
saddle at which it stayed apart from a higher one, or ε if it never met one: its
prominence is its peak above that base (what the birth test of a contact looks at).

Cost: a frame whose every connected patch has a single maximum (a smooth press: the
common case) is recognised by ``count_peaks``, one gather and one maximum over the
nodes' rows of the mesh's neighbour table, and needs nothing more; otherwise the
watershed is a handful of array operations over the deformed nodes and a Python merge
over the few basins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import SkinMesh

__all__ = ["MeshGraph", "Segments", "Watershed", "count_peaks"]


class MeshGraph:
    """A mesh's adjacency as a table: row i is node i, then its neighbours, padded with ``n_nodes``.

    A table (not a ragged list) makes every per-set gather one indexing operation:
    ``table[deformed]`` is the neighbourhood of a deformed set, and a value array
    one longer than the mesh, ending in -inf, makes the padding lose every
    comparison. ``local`` is scratch: node -> its place in a deformed set (-1 elsewhere).
    """

    __slots__ = ("local", "table", "width")

    def __init__(self, mesh: SkinMesh) -> None:
        indptr, indices = mesh.neighbour_csr
        n = mesh.n_nodes
        degree = np.diff(indptr)
        table = np.full((n, int(degree.max(initial=0)) + 1), n, dtype=np.int64)
        table[:, 0] = np.arange(n)
        column = np.arange(len(indices)) - np.repeat(indptr[:-1], degree) + 1
        table[np.repeat(np.arange(n), degree), column] = indices
        self.table, self.width = table, table.shape[1]
        self.local = np.full(n + 1, -1, dtype=np.int64)

    def neighbours_of(self, deformed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, their neighbour columns flattened, the start of each node's in that): a deformed
        set's part of the table, and what ``count_peaks`` gathers."""
        rows = self.table[deformed]
        flat = rows[:, 1:].ravel()
        return rows, flat, np.arange(0, flat.size, self.width - 1)


def count_peaks(flat: np.ndarray, starts: np.ndarray, field: np.ndarray, w: np.ndarray) -> int:
    """How many of a set's nodes are at least as high as all their neighbours (ties count each).

    ``flat``, ``starts``: the set's neighbours (``MeshGraph.neighbours_of``); ``field``: every
    node's value and a last -inf; ``w``: the set's values. A neighbour outside the set is below
    ε, so below every node of the set. Three array operations: the common single-peak frame
    pays only these for its segmentation.
    """
    return int(np.count_nonzero(np.maximum.reduceat(field[flat], starts) <= w))


@dataclass(frozen=True, slots=True)
class Segments:
    """The deformed set split by peak: ``order`` lists the set's indices grouped by segment (ascending
    within each), ``counts`` each segment's size; per segment its ``base`` (mm). ``key`` is the same
    bytes whenever the grouping is the same (a caller may keep what it built on it)."""

    order: np.ndarray
    counts: np.ndarray
    base: list[float]
    key: bytes


class Watershed:
    """The watershed of one deformed set, frame after frame.

    The set's own graph (its nodes' neighbours in the set's indices, its inner edges)
    is built once. Basins and the edge that is each pair of adjacent basins' saddle
    depend only on the order of the values, not on the values: while a press is held
    (or scaled) the order stays, and a frame pays only for the merge test on the new
    peak and saddle values. The final grouping is kept too and returned as is while
    the merges come out the same.
    """

    __slots__ = ("_basins", "_grouping", "_merged", "_order", "dst", "n", "nb", "src")

    def __init__(self, graph: MeshGraph, deformed: np.ndarray, rows: np.ndarray) -> None:
        n = self.n = len(deformed)
        local = graph.local
        local[deformed] = np.arange(n)
        nb = self.nb = local[rows]  # the set's own indices; -1 outside it (and for the padding)
        local[deformed] = -1
        src, col = np.nonzero(nb > np.arange(n)[:, None])  # each edge inside the set once
        self.src, self.dst = src, nb[src, col]
        self._order = b""  # the order the basins were found in, as bytes
        self._basins: tuple[np.ndarray, int, list[int], np.ndarray] | None = None
        self._merged: list[int] | None = None
        self._grouping: Segments | None = None

    def split(self, w: np.ndarray, floor: float, merge_mm: float, merge_ratio: float) -> Segments:
        """The set (values ``w``) split into peaks; ``floor``: ε."""
        # a total order: values within a picometre tie (a symmetric press's mirror nodes differ in their
        # last bits from frame to frame), and ties go to the later node
        order = np.argsort(np.rint(w * 1e9), kind="stable")
        key = order.tobytes()
        if self._basins is None or key != self._order:
            self._basins = self._find_basins(w, order)
            self._order = key
            self._grouping = None
        label, k, keys, ends = self._basins
        values = w[ends].tolist()  # the peaks, then both ends of each pair's saddle edge: one gather
        peak = values[:k]
        base = [floor] * k
        roots = list(range(k))
        if keys:
            m = len(keys)
            saddles = [min(a, b) for a, b in zip(values[k:k + m], values[k + m:], strict=True)]
            roots = _merge(k, keys, saddles, peak, base, merge_mm, merge_ratio)
        last = self._grouping
        if last is None or roots != self._merged:
            final = np.asarray(roots, dtype=np.int64)[label]
            grouped = np.argsort(final, kind="stable")
            counts = np.bincount(final)
            kept = np.flatnonzero(counts)
            key = grouped.tobytes() + counts.tobytes()
            last = self._grouping = Segments(grouped, counts[kept], [], key)
            self._merged = roots
        kept_roots = sorted(set(roots))
        return Segments(last.order, last.counts, [base[r] for r in kept_roots], last.key)

    def _find_basins(self, w: np.ndarray, order: np.ndarray) -> tuple[np.ndarray, int, list[int], np.ndarray]:
        """(each node's basin, how many, adjacent pairs as a * k + b, the nodes whose values the merge
        needs: the peaks, then each pair's saddle edge's ends, all the first ends then all the second)."""
        n = self.n
        rank = np.empty(n + 1, dtype=np.int64)
        rank[order] = np.arange(n)
        rank[n] = -1  # nb == -1 reads this: below every node
        parent = order[rank[self.nb].max(axis=1)]  # the highest of itself and its neighbours
        while True:  # pointer jumping: every node to the top of its ascent
            up = parent[parent]
            if np.array_equal(up, parent):
                break
            parent = up
        tops = np.flatnonzero(parent == np.arange(n))
        k = len(tops)
        label = np.empty(n, dtype=np.int64)
        label[tops] = np.arange(k)
        label = label[parent]
        if k == 1 or not len(self.src):
            return label, k, [], tops
        src, dst = self.src, self.dst
        la, lb = label[src], label[dst]
        cross = np.flatnonzero(la != lb)
        if not cross.size:
            return label, k, [], tops
        level = np.minimum(w[src[cross]], w[dst[cross]])
        key = np.minimum(la[cross], lb[cross]) * k + np.maximum(la[cross], lb[cross])
        by_level = np.argsort(-level, kind="stable")
        keys, first = np.unique(key[by_level], return_index=True)
        edge = cross[by_level[first]]  # each pair's highest crossing edge: its saddle
        return label, k, keys.tolist(), np.concatenate([tops, src[edge], dst[edge]])


def _merge(k: int, keys: list[int], saddles: list[float], peak: list[float], base: list[float],
           merge_mm: float, merge_ratio: float) -> list[int]:
    """The merge tree over ``k`` basins: pairs (``keys`` = a * k + b) from the highest saddle down;
    each basin's root (the basin it ended in). ``peak`` and ``base`` are updated in place."""
    up = list(range(k))

    def find(a: int) -> int:
        while up[a] != a:
            up[a] = up[up[a]]
            a = up[a]
        return a

    for i in sorted(range(len(keys)), key=lambda j: -saddles[j]):
        a, b = find(keys[i] // k), find(keys[i] % k)
        if a == b:
            continue
        if peak[a] < peak[b] or (peak[a] == peak[b] and a > b):
            a, b = b, a  # a: the elder (higher) basin
        s = saddles[i]
        drop = peak[b] - s
        if drop <= merge_mm or drop <= merge_ratio * peak[b]:
            up[b] = a  # not significantly below the lower peak: one contact
        elif s > base[b]:
            base[b] = s
    return [find(a) for a in range(k)]
