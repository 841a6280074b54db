"""Feature statistics as lerobot computes them (``lerobot/datasets/compute_stats.py``, v0.6.1), an episode
at a time without holding it.

lerobot stacks an episode's values and calls ``RunningQuantileStats.update`` once on them, reshaped to
``(-1, shape[-1])`` (so an N x 3 field has stats of shape (3,), a 16 x 16 grid (16,), a scalar (1,)):
min, max, mean, std (``sqrt(max(0, E[x²] - E[x]²))``), count (the episode's frames) and q01, q10,
q50, q90, q99 read off a histogram of 5000 bins between ``min - 1e-10`` and ``max + 1e-10``
(``linspace`` in the values' dtype, float32 for float32, float64 for integers). Here the same comes
from two passes over the episode's blocks: the first finds min, max and the sums and spills the values
to a file (raw, an episode can be an hour), the second reads them back and fills the histogram with
those final edges, so every count, and with it every quantile, is what the one-shot call gives; the sums
are float64 where lerobot's ``np.mean`` is float32 (the two agree to float32's rounding). An episode
has at least two frames (``export.py`` refuses shorter ones): on one frame lerobot's
``_compute_basic_stats`` keeps every axis of a field (N x 3 stats), which its own ``aggregate_stats``
then cannot fold with the others.

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

from pathlib import Path
from typing import BinaryIO

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


def _quantiles(hists: np.ndarray, edges: np.ndarray, elements: int) -> dict[str, np.ndarray]:
    """lerobot's ``_compute_single_quantile`` for every column at once: the bin where the cumulative count
    reaches ``q * elements`` (its first edge if none is before it, the last edge if never), linear within
    it (its left edge if it is empty)."""
    cum = np.cumsum(hists, axis=1)
    cols = np.arange(len(hists))
    out = {}
    for q, key in zip(QUANTILES, _KEYS, strict=True):
        target = q * elements
        idx = (cum < target).sum(axis=1)  # searchsorted(cumsum, target), side left
        inner = np.clip(idx, 1, cum.shape[1] - 1)
        before = cum[cols, inner - 1]
        inside = cum[cols, inner] - before
        left, right = edges[cols, inner], edges[cols, inner + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            value = np.where(
                inside == 0,
                left,
                left + (target - before) / np.where(inside == 0, 1, inside) * (right - left),
            )
        value = np.where(idx == 0, edges[:, 0], np.where(idx >= cum.shape[1], edges[:, -1], value))
        out[key] = value
    return out


def _finish(
    lo: np.ndarray,
    hi: np.ndarray,
    mean: np.ndarray,
    mean_sq: np.ndarray,
    hists: np.ndarray,
    edges: np.ndarray,
    elements: int,
    frames: int,
) -> Stats:
    out: Stats = {
        "min": lo.copy(),
        "max": hi.copy(),
        "mean": mean.astype(lo.dtype),
        "std": np.sqrt(np.maximum(0, mean_sq - mean**2)).astype(lo.dtype),
        "count": np.array([frames]),
    }
    out.update(_quantiles(hists, edges, elements))
    return out


class FeatureStats:
    """One numeric feature's stats over one episode: ``first`` on every block, then ``result``.

    The second pass needs the values again: ``first`` spills each non-zero one with its column (two raw
    files, ``spill`` + ``.cols``/``.vals``) and counts the zeros, as a skin's field is mostly zeros (20
    nodes pressed of 700); ``result`` reads the spill back a few MB at a time."""

    def __init__(self, dtype: str, shape: tuple[int, ...], spill: Path) -> None:
        self.work = np.result_type(np.dtype(dtype), np.float32)
        self.width = shape[-1]
        self.scalar = tuple(shape) == (1,)
        self.frames = 0
        self.elements = 0
        self.lo: np.ndarray | None = None
        self.hi: np.ndarray | None = None
        self.total = np.zeros(self.width)
        self.total_sq = np.zeros(self.width)
        self.zeros = np.zeros(self.width, np.int64)
        self.paths = (spill.with_suffix(".cols"), spill.with_suffix(".vals"))
        self._out: tuple[BinaryIO, BinaryIO] | None = None

    def first(self, block: np.ndarray) -> None:
        rows = np.ascontiguousarray(np.asarray(block).reshape(-1, self.width), dtype=self.work)
        if not len(rows):
            return
        self.frames += len(block)
        self.elements += len(rows)
        w = self.width
        at = np.flatnonzero(rows)  # every sum and extreme from the non-zero values alone
        cols = (at % w).astype(np.int32)
        vals = rows.ravel()[at]
        zeros = len(rows) - np.bincount(cols, minlength=w)
        self.zeros += zeros
        wide = vals.astype(np.float64)
        self.total += np.bincount(cols, weights=wide, minlength=w)
        self.total_sq += np.bincount(cols, weights=wide * wide, minlength=w)
        lo, hi = np.full(w, np.inf, self.work), np.full(w, -np.inf, self.work)
        np.minimum.at(lo, cols, vals)
        np.maximum.at(hi, cols, vals)
        lo, hi = np.where(zeros > 0, np.minimum(lo, 0), lo), np.where(zeros > 0, np.maximum(hi, 0), hi)
        self.lo = lo if self.lo is None else np.minimum(self.lo, lo)
        self.hi = hi if self.hi is None else np.maximum(self.hi, hi)
        if self._out is None:
            self._out = (self.paths[0].open("wb"), self.paths[1].open("wb"))
        cols.tofile(self._out[0])
        vals.tofile(self._out[1])

    def _histograms(self) -> tuple[np.ndarray, np.ndarray]:
        """The second pass: every value's bin as ``np.histogram(column, bins=edges)`` gives it (bins
        [e_j, e_j+1), the last one closed), found by arithmetic on the uniform edges, then put right by
        comparing with the edges themselves (in lerobot's dtype)."""
        assert self.lo is not None and self.hi is not None and self._out is not None
        self.close()
        w = self.width
        edges = np.stack([np.linspace(self.lo[i] - 1e-10, self.hi[i] + 1e-10, BINS + 1) for i in range(w)])
        flat, row = edges.ravel(), np.arange(w) * (BINS + 1)
        first, step = edges[:, 0], (edges[:, -1] - edges[:, 0]) / BINS
        step = np.where(step > 0, step, 1)
        counts = np.zeros(w * BINS, np.int64)
        with self.paths[0].open("rb") as fc, self.paths[1].open("rb") as fv:
            while len(cols := np.fromfile(fc, np.int32, 1 << 20)):
                vals = np.fromfile(fv, self.work, len(cols))
                b = np.clip(((vals - first[cols]) / step[cols]).astype(np.int64), 0, BINS - 1)
                for _ in range(2):  # the arithmetic is off by one bin at most, next to an edge
                    b -= (vals < flat[row[cols] + b]) & (b > 0)
                    b += (vals >= flat[row[cols] + b + 1]) & (b < BINS - 1)
                counts += np.bincount(cols * BINS + b, minlength=w * BINS)
        zero_bin = np.clip((edges <= 0).sum(axis=1) - 1, 0, BINS - 1)  # searchsorted(edges, 0, "right") - 1
        counts[np.arange(w) * BINS + zero_bin] += self.zeros
        for path in self.paths:
            path.unlink()
        return counts.reshape(w, BINS), edges

    def result(self) -> Stats:
        assert self.lo is not None and self.hi is not None
        hists, edges = self._histograms()
        n = self.elements
        out = _finish(self.lo, self.hi, self.total / n, self.total_sq / n, hists, edges, n, self.frames)
        if self.scalar:  # lerobot keeps (1,) features 1-D: reshaped to (1,)
            out = {k: v if k == "count" else np.asarray(v).reshape(1) for k, v in out.items()}
        return out

    def close(self) -> None:
        if self._out is not None:
            for f in self._out:
                f.close()


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
        st = _finish(
            np.array(lo),
            np.array(hi),
            np.array(mean),
            np.array(mean_sq),
            np.array(hists),
            np.array(edges),
            int(self.counts[0].sum()),
            self.sampled,
        )
        return {
            k: v if k == "count" else (np.asarray(v, np.float64) / 255.0).reshape(3, 1, 1)
            for k, v in st.items()
        }


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
        agg: Stats = {
            "min": np.min(np.stack([s["min"] for s in parts]), axis=0),
            "max": np.max(np.stack([s["max"] for s in parts]), axis=0),
            "mean": mean,
            "std": np.sqrt(variance),
            "count": count,
        }
        for q in _KEYS:
            if all(q in s for s in parts):
                agg[q] = (np.stack([s[q] for s in parts]) * counts).sum(axis=0) / count
        out[key] = agg
    return out
