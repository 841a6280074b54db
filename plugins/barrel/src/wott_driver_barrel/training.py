"""Fitting the default displacement model: a local ridge map, marker motion -> node displacement.

Why linear, and why local (docs/barrel-vision.md has the numbers): on
simulated presses a dense ridge map from all 1024 marker coordinates to all
1755 node values is as accurate as a small MLP trained on the same data (the
error left is what 256 markers cannot see between them, not nonlinearity),
but it is 7 MB. A node only depends on the markers near it, so each node
keeps the markers within ``radius_mm`` of it (about 70 of 256 at 40 mm): the
same accuracy in 0.5 MB, and a few microseconds per frame.

The fit needs only the Gram matrices of the training set (``X^T X``,
``X^T Y``), so each node's ridge problem is a small solve on a sub-block.
Detector noise (``noise_px``) enters as its expected contribution to the Gram
matrix (``S * sigma^2 * I``), the closed form of training on noisy copies.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .geometry import BarrelLayout

__all__ = ["LocalRidge", "fit_dense_ridge", "fit_local_ridge", "rmse_mm"]


@dataclass
class LocalRidge:
    """y = b + sum over each node's own features: ``y[3i:3i+3] = x[index[i]] @ weight[i]``."""

    index: np.ndarray  # (n_free, K) int64 feature indices (padded with 0 and zero weights)
    weight: np.ndarray  # (n_free, K, 3) float32
    bias: np.ndarray  # (3 * n_free,) float32
    info: dict[str, Any] = field(default_factory=dict)

    def predict(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, dtype=np.float32))
        gathered = x[:, self.index]  # (B, n_free, K)
        y = np.einsum("bnk,nkj->bnj", gathered, self.weight).reshape(len(x), -1)
        out: np.ndarray = y + self.bias
        return out

    @property
    def n_parameters(self) -> int:
        return int(self.weight.size + self.bias.size)


def _feature_columns(layout: BarrelLayout, markers: np.ndarray) -> np.ndarray:
    """Model input columns of the given markers: camera c, marker m, axis a -> c*2M + 2m + a."""
    m = layout.markers.n_markers
    return np.concatenate([c * 2 * m + 2 * markers + a
                           for c in range(len(layout.cameras)) for a in (0, 1)])


def _centred_gram(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    mx, my = x.mean(axis=0), y.mean(axis=0)
    xc = x - mx
    return xc.T @ xc, xc.T @ (y - my), mx, my


def fit_local_ridge(layout: BarrelLayout, x: np.ndarray, y: np.ndarray, *, radius_mm: float = 40.0,
                    lam: float = 1.0, noise_px: float = 0.05) -> LocalRidge:
    gram, cross, mx, my = _centred_gram(x, y)
    gram[np.diag_indices_from(gram)] += len(x) * noise_px**2 + lam
    free = layout.mesh.free_indices
    nodes = layout.mesh.nodes[free]
    dist = np.linalg.norm(nodes[:, None, :] - layout.markers.rest[None, :, :], axis=2)
    cols = [_feature_columns(layout, np.flatnonzero(dist[i] < radius_mm)) for i in range(len(free))]
    if min(len(c) for c in cols) == 0:
        raise ValueError(f"radius {radius_mm} mm leaves a node without markers")
    k = max(len(c) for c in cols)
    index = np.zeros((len(free), k), np.int64)
    weight = np.zeros((len(free), k, 3), np.float32)
    bias = np.zeros(3 * len(free))
    for i, f in enumerate(cols):
        w = np.linalg.solve(gram[np.ix_(f, f)], cross[f][:, 3 * i : 3 * i + 3])
        index[i, : len(f)] = f
        weight[i, : len(f)] = w
        bias[3 * i : 3 * i + 3] = my[3 * i : 3 * i + 3] - mx[f] @ w
    info = {"kind": "local-ridge", "radius_mm": radius_mm, "lambda": lam, "noise_px": noise_px,
            "features_per_node_mean": float(np.mean([len(c) for c in cols])), "samples": len(x)}
    return LocalRidge(index, weight, bias.astype(np.float32), info)


def fit_dense_ridge(x: np.ndarray, y: np.ndarray, *, lam: float = 1.0,
                    noise_px: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """(W (F, O), b (O,)): the dense comparison model (too big to ship, see module doc)."""
    gram, cross, mx, my = _centred_gram(x, y)
    gram[np.diag_indices_from(gram)] += len(x) * noise_px**2 + lam
    w = np.linalg.solve(gram, cross)
    return w.astype(np.float32), (my - mx @ w).astype(np.float32)


def rmse_mm(pred: np.ndarray, truth: np.ndarray, *, min_norm_mm: float = 0.0) -> float:
    """RMS over nodes of the error vector's norm (mm); ``min_norm_mm`` keeps only nodes deformed more."""
    e = (np.asarray(pred) - np.asarray(truth)).reshape(len(truth), -1, 3)
    sq = np.einsum("snj,snj->sn", e, e)
    if min_norm_mm > 0:
        t = np.asarray(truth).reshape(len(truth), -1, 3)
        sq = sq[np.linalg.norm(t, axis=2) > min_norm_mm]
    return float(np.sqrt(np.mean(sq))) if sq.size else 0.0
