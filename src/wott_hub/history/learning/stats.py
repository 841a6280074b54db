"""Feature statistics as lerobot computes them (``lerobot/datasets/compute_stats.py``, v0.6.1), an episode
at a time without holding it.

lerobot stacks an episode's values and calls ``RunningQuantileStats.update`` once on them, reshaped to
``(-1, shape[-1])`` (so an N x 3 field has stats of shape (3,), a 16 x 16 grid (16,), a scalar (1,)):
min, max, mean, std (``sqrt(max(0, E[x²] - E[x]²))``), count (the episode's frames) and q01, q10,
q50, q90, q99 read off a histogram of 5000 bins between ``min - 1e-10`` and ``max + 1e-10``
(``linspace`` in the values' dtype, float32 for float32, float64 for integers). Here the same comes
from two passes over the episode's blocks: the first finds min, max and the sums, the second fills the
histogram with those final edges, so every count, and with it every quantile, is what the one-shot
call gives; the sums are float64 where lerobot's ``np.mean`` is float32 (the two agree to float32's
rounding). An episode has at least two frames (``export.py`` refuses shorter ones): on one frame
lerobot's ``_compute_basic_stats`` keeps every axis of a field (N x 3 stats), which its own
``aggregate_stats`` then cannot fold with the others.

Camera images: lerobot samples ``sample_indices(frames)`` of an episode's images, keeps every
``int(width / 150)``-th row and column of those of 300 px or more (``auto_downsample_height_width``),
and reduces over all but the channel, divided by 255, shaped (3, 1, 1). 8-bit values have 256 levels:
counting them per channel (``ImageStats``) gives min, max, mean and the histogram exactly, in
constant memory.

Episodes are folded into the dataset's stats one after the other as lerobot's ``save_episode`` does
(``aggregate_stats([stats, episode])``: weighted means, the parallel variance, count-weighted
quantiles).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["QUANTILES", "FeatureStats", "ImageStats", "aggregate", "auto_downsample", "sample_indices"]

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
_KEYS = [f"q{int(q * 100):02d}" for q in QUANTILES]
BINS = 5000

Stats = dict[str, np.ndarray]


def sample_indices(frames: int) -> list[int]:
    """lerobot's ``sample_indices``: the frames of an episode whose images its stats use."""
    lo, hi, power = 100, 10_000, 0.75
    if frames < lo:
        lo = frames
    num = max(lo, min(int(frames**power), hi))
    return [int(i) for i in np.round(np.linspace(0, frames - 1, num)).astype(int)]


def auto_downsample(height: int, width: int, target: int = 150, threshold: int = 300) -> int:
    """lerobot's ``auto_downsample_height_width`` as its step (1: the image as it is)."""
    if max(width, height) < threshold:
        return 1
    return int(width / target) if width > height else int(height / target)


def _quantile(hist: np.ndarray, edges: np.ndarray, target: float) -> Any:
    """lerobot's ``_compute_single_quantile``."""
    cumsum = np.cumsum(hist)
    idx = int(np.searchsorted(cumsum, target))
    if idx == 0:
        return edges[0]
    if idx >= len(cumsum):
        return edges[-1]
    before = cumsum[idx - 1]
    inside = cumsum[idx] - before
    if inside == 0:
        return edges[idx]
    return edges[idx] + (target - before) / inside * (edges[idx + 1] - edges[idx])


def _finish(lo: np.ndarray, hi: np.ndarray, mean: np.ndarray, mean_sq: np.ndarray, hists: list[np.ndarray],
            edges: list[np.ndarray], elements: int, frames: int) -> Stats:
    out: Stats = {"min": lo.copy(), "max": hi.copy(), "mean": mean.astype(lo.dtype),
                  "std": np.sqrt(np.maximum(0, mean_sq - mean**2)).astype(lo.dtype),
                  "count": np.array([frames])}
    for q, key in zip(QUANTILES, _KEYS, strict=True):
        out[key] = np.array([_quantile(h, e, q * elements) for h, e in zip(hists, edges, strict=True)])
    return out


class FeatureStats:
    """One numeric feature's stats over one episode: ``first`` on every block, then ``second`` on every
    block again, then ``result``."""

    def __init__(self, dtype: str, shape: tuple[int, ...]) -> None:
        self.work = np.result_type(np.dtype(dtype), np.float32)
        self.width = shape[-1]
        self.scalar = tuple(shape) == (1,)
        self.frames = 0
        self.elements = 0
        self.lo: np.ndarray | None = None
        self.hi: np.ndarray | None = None
        self.total = np.zeros(self.width)
        self.total_sq = np.zeros(self.width)
        self.hists = [np.zeros(BINS) for _ in range(self.width)]
        self.edges: list[np.ndarray] = []

    def _rows(self, block: np.ndarray) -> np.ndarray:
        return np.asarray(block).reshape(-1, self.width).astype(self.work, copy=False)

    def first(self, block: np.ndarray) -> None:
        rows = self._rows(block)
        if not len(rows):
            return
        self.frames += len(block)
        self.elements += len(rows)
        lo, hi = rows.min(axis=0), rows.max(axis=0)
        self.lo = lo if self.lo is None else np.minimum(self.lo, lo)
        self.hi = hi if self.hi is None else np.maximum(self.hi, hi)
        wide = rows.astype(np.float64)
        self.total += wide.sum(axis=0)
        self.total_sq += (wide * wide).sum(axis=0)

    def second(self, block: np.ndarray) -> None:
        assert self.lo is not None and self.hi is not None
        if not self.edges:
            self.edges = [np.linspace(self.lo[i] - 1e-10, self.hi[i] + 1e-10, BINS + 1) for i in range(self.width)]
        rows = self._rows(block)
        for i in range(self.width):
            self.hists[i] += np.histogram(rows[:, i], bins=self.edges[i])[0]

    def result(self) -> Stats:
        assert self.lo is not None and self.hi is not None
        n = self.elements
        out = _finish(self.lo, self.hi, self.total / n, self.total_sq / n, self.hists, self.edges, n, self.frames)
        if self.scalar:  # lerobot keeps (1,) features 1-D: reshaped to (1,)
            out = {k: v if k == "count" else np.asarray(v).reshape(1) for k, v in out.items()}
        return out


class ImageStats:
    """A camera's stats over one episode, from the images of the frames ``sample_indices`` picks."""

    def __init__(self, frames: int) -> None:
        self.wanted = sample_indices(frames)
        self.counts = np.zeros((3, 256), np.int64)
        self.sampled = 0

    def add(self, image: np.ndarray, times: int = 1) -> None:
        """``image`` (H x W x 3 uint8) is the picture of ``times`` of the sampled frames."""
        step = auto_downsample(image.shape[0], image.shape[1])
        small = image[::step, ::step]
        for c in range(3):
            self.counts[c] += np.bincount(small[:, :, c].ravel(), minlength=256) * times
        self.sampled += times

    def result(self) -> Stats:
        levels = np.arange(256, dtype=np.float32)
        lo, hi, mean, mean_sq, hists, edges = [], [], [], [], [], []
        for c in range(3):
            present = np.nonzero(self.counts[c])[0]
            cmin, cmax = np.float32(present[0]), np.float32(present[-1])
            total = self.counts[c].sum()
            lo.append(cmin)
            hi.append(cmax)
            mean.append((self.counts[c] * np.arange(256)).sum() / total)
            mean_sq.append((self.counts[c] * np.arange(256) ** 2).sum() / total)
            e = np.linspace(cmin - 1e-10, cmax + 1e-10, BINS + 1)
            edges.append(e)
            hists.append(np.histogram(levels, bins=e, weights=self.counts[c])[0])
        st = _finish(np.array(lo), np.array(hi), np.array(mean), np.array(mean_sq), hists, edges,
                     int(self.counts[0].sum()), self.sampled)
        return {k: v if k == "count" else (np.asarray(v, np.float64) / 255.0).reshape(3, 1, 1) for k, v in st.items()}


def aggregate(total: dict[str, Stats] | None, episode: dict[str, Stats]) -> dict[str, Stats]:
    """lerobot's ``aggregate_stats([total, episode])`` (``episode`` alone when ``total`` is None)."""
    if total is None:
        return episode
    out: dict[str, Stats] = {}
    for key in total.keys() | episode.keys():
        parts = [s[key] for s in (total, episode) if key in s]
        means = np.stack([s["mean"] for s in parts])
        variances = np.stack([s["std"] ** 2 for s in parts])
        counts = np.stack([s["count"] for s in parts])
        count = counts.sum(axis=0)
        while counts.ndim < means.ndim:
            counts = np.expand_dims(counts, axis=-1)
        mean = (means * counts).sum(axis=0) / count
        variance = ((variances + (means - mean) ** 2) * counts).sum(axis=0) / count
        agg: Stats = {"min": np.min(np.stack([s["min"] for s in parts]), axis=0),
                      "max": np.max(np.stack([s["max"] for s in parts]), axis=0),
                      "mean": mean, "std": np.sqrt(variance), "count": count}
        for q in _KEYS:
            if all(q in s for s in parts):
                agg[q] = (np.stack([s[q] for s in parts]) * counts).sum(axis=0) / count
        out[key] = agg
    return out
