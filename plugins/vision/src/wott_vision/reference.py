"""Rest references with markers missing: detections matched to the expected marker positions.

A printed marker can be painted out, merged with its neighbour or hidden by
dirt; a device that insists on seeing every marker at rest never starts (issue
14). ``match_expected`` places the detections of a rest image on the marker
positions a device expects (its camera model's projection of the rest
markers): a common shift is estimated first (the camera sits a little off its
nominal place), then every detection within a fraction of its marker's
spacing to its neighbours takes that marker. A blob between two markers (two
merged) or far from any marker (a speck) takes none; a marker taken by no
detection is *unavailable*. A device keeps going with the rest, reports the
unavailable markers in its health and never reports their nodes as deformed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MatchResult", "match_expected"]


class MatchResult:
    """``px`` (M, 2): matched detections, expected positions (shifted) where unavailable;
    ``available`` (M,) bool."""

    __slots__ = ("available", "px")

    def __init__(self, px: np.ndarray, available: np.ndarray) -> None:
        self.px, self.available = px, available

    @property
    def unavailable(self) -> np.ndarray:
        return np.flatnonzero(~self.available)


def _spacing(expected: np.ndarray) -> np.ndarray:
    """Distance from each expected marker to its nearest neighbour (px)."""
    d = np.linalg.norm(expected[:, None, :] - expected[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    nearest: np.ndarray = d.min(axis=1)
    return nearest


def match_expected(points: np.ndarray, expected: np.ndarray, *, gate_fraction: float = 0.3,
                   iterations: int = 3) -> MatchResult:
    """Match detections ``points`` (K, 2) to ``expected`` (M, 2) marker positions (see module doc)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    expected = np.asarray(expected, dtype=np.float64)
    m = len(expected)
    gate = gate_fraction * _spacing(expected)
    shift = np.zeros(2)
    owner = np.full(m, -1)
    for it in range(iterations + 1):
        owner[:] = -1
        if not len(points):
            break
        moved = expected + shift
        d = np.linalg.norm(points[:, None, :] - moved[None, :, :], axis=2)  # (K, M)
        nearest = d.argmin(axis=1)
        dist = d[np.arange(len(points)), nearest]
        # loosely on the first pass (the shift is unknown), then within the gate
        limit = gate[nearest] * (1.6 if it == 0 else 1.0)
        best = np.full(m, np.inf)
        for k in np.argsort(dist):
            j = nearest[k]
            if dist[k] <= limit[k] and dist[k] < best[j]:
                best[j], owner[j] = dist[k], k
        taken = owner >= 0
        if not taken.any():
            break
        if it < iterations:
            shift = np.median(points[owner[taken]] - expected[taken], axis=0)
    available = owner >= 0
    px = expected + shift
    px[available] = points[owner[available]]
    return MatchResult(px, available)
