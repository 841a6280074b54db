"""Which detection is which marker, frame after frame.

A skin's markers move a fraction of their spacing between two frames at
camera rates, so each marker takes the nearest detection to where it was last
seen (``scipy.spatial.cKDTree``), within a gate of ``gate_fraction`` of its
distance to its nearest neighbour in the reference: on a fisheye image the
spacing varies tenfold (far markers are a few pixels apart, near ones fifty),
and one global gate would either swap the small ones or lose the big ones.

Two markers pressed together merge into one blob whose centroid lies between
them; giving it to either would make that marker follow its neighbour after
they part (an identity swap that never heals). So a detection claimed by two
markers goes to the closer only when it is clearly closer (``ambiguity``);
otherwise to neither. A lost marker is not frozen: its search position moves
with the median motion of its tracked neighbours, and it is also searched for
at its reference position, so it is found again where it reappears, mid-press
or after release. That second search takes only a detection no tracked guess
reached: a dot two lost markers contested (both guesses in their gates, neither
clearly closer) is one of the two, and giving it to one by its rest position
swaps them (seen in a deep pinch on the barrel: two markers squeezed into one
blob for half a second, then the one whose rest position lay nearer took its
neighbour's dot). ``estimate`` holds that best guess for every marker.

And a frame that shows the grid at rest re-acquires it: when every detection lies
within ``home_fraction`` of a spacing of one marker's rest position, one per marker,
and they cover at least ``rest_fraction`` of the markers, each marker takes the dot
at its home, whatever it tracked before (a marker with no dot at home, one not seen
or pressed beyond it, keeps its guess). Tracking history cannot be trusted more than
that picture: two markers that swapped identities in a pinch (a merged blob, a guess
left behind while its neighbours moved apart) would otherwise stay swapped after the
release, and the model would read a dent in a skin at rest for as long as the device
runs. A light press moves no dot that far, so it re-acquires the same identities.

``predict`` adds the marker's last velocity to its search position (helps fast
slides at low fps). ``assignment="optimal"`` replaces the greedy claim by a
minimum-cost matching (``scipy.optimize.linear_sum_assignment``); it is slower
and, at camera rates, rarely different.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["MarkerTracker"]

ASSIGNMENTS = ("greedy", "optimal")


class MarkerTracker:
    """Track M reference markers through frames of detections (K, 2) -> (M, 2), NaN when lost."""

    def __init__(
        self,
        reference: np.ndarray,
        *,
        gate_fraction: float = 0.45,
        max_gate_px: float = 25.0,
        min_gate_px: float = 1.0,
        predict: bool = False,
        assignment: str = "greedy",
        ambiguity: float = 0.6,
        neighbours: int = 6,
        merge_ratio: float = 1.45,
        reference_area: np.ndarray | None = None,
        home_fraction: float = 0.25,
        rest_fraction: float = 0.9,
    ) -> None:
        ref = np.asarray(reference, dtype=np.float64)
        if ref.ndim != 2 or ref.shape[1] != 2 or len(ref) == 0:
            raise ValueError(f"reference must be an (M, 2) array with M > 0, got shape {ref.shape}")
        if not np.isfinite(ref).all():
            raise ValueError("reference positions must be finite")
        if assignment not in ASSIGNMENTS:
            raise ValueError(f"assignment must be one of {ASSIGNMENTS}, got {assignment!r}")
        if not 0 < gate_fraction <= 1 or not 0 < min_gate_px <= max_gate_px:
            raise ValueError("need 0 < gate_fraction <= 1 and 0 < min_gate_px <= max_gate_px")
        if not 0 < ambiguity <= 1:
            raise ValueError(f"ambiguity must lie in (0, 1], got {ambiguity}")
        if not 0 < home_fraction <= 0.5:  # beyond half a spacing, a dot is nearer another marker's home
            raise ValueError(f"home_fraction must lie in (0, 0.5], got {home_fraction}")
        if not 0 < rest_fraction <= 1:
            raise ValueError(f"rest_fraction must lie in (0, 1], got {rest_fraction}")
        self.reference = ref
        self.predict = predict
        self.assignment = assignment
        self.ambiguity = float(ambiguity)
        self.merge_ratio = float(merge_ratio)
        self.reference_area = None if reference_area is None else np.asarray(reference_area, float)
        if self.reference_area is not None and self.reference_area.shape != (len(ref),):
            raise ValueError(f"reference_area must have shape ({len(ref)},)")
        if len(ref) > 1:
            k = min(neighbours, len(ref) - 1) + 1
            nn, idx = cKDTree(ref).query(ref, k=k)
            spacing = nn[:, 1]
            self._neighbours = idx[:, 1:]
        else:
            spacing = np.full(1, max_gate_px / gate_fraction)
            self._neighbours = np.zeros((1, 0), dtype=np.int64)
        self.gate = np.clip(gate_fraction * spacing, min_gate_px, max_gate_px)
        self.home = np.minimum(home_fraction * spacing, self.gate)  # "back home" radius per marker
        self.rest_fraction = float(rest_fraction)
        self._ref_tree = cKDTree(ref)
        self.rest_frames = 0  # frames that showed the grid at rest (identities taken from it)
        self.reset()

    def reset(self) -> None:
        """Forget the motion: every marker is searched for at its reference position again."""
        self.last = self.reference.copy()  # last seen (or, when lost, best guessed) position
        self.match = np.full(len(self.reference), -1, dtype=np.int64)  # index into the last points
        self.velocity = np.zeros_like(self.reference)
        self.lost = np.zeros(len(self.reference), dtype=bool)

    @property
    def estimate(self) -> np.ndarray:
        """Best position of every marker (M, 2): where seen, or where its neighbours carried it."""
        return self.last

    def track(self, points: np.ndarray, areas: np.ndarray | None = None) -> np.ndarray:
        """Positions (M, 2) of the markers in this frame's detections, NaN rows for the lost.

        ``areas`` (K,), the blobs' pixel counts (``MarkerDetector.areas``), lets the
        tracker refuse a blob more than ``merge_ratio`` times its marker's reference
        area: two markers pressed into one. Without ``reference_area`` the areas of
        the first frame given with areas are taken as the reference (skin at rest).
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        valid = np.flatnonzero(np.isfinite(pts).all(axis=1))
        pts = pts[valid]
        m = len(self.reference)
        out = np.full((m, 2), np.nan)
        if len(pts):
            owner = self._at_rest(pts)
            if owner is None:
                guess = self.last + self.velocity if self.predict else self.last
                taken = np.zeros(len(pts), dtype=bool)  # claimed by a guess, given or contested
                owner = self._match(pts, guess, np.ones(m, dtype=bool), taken)
                retry = (owner < 0) & self.lost  # lost for a while: it may be back home
                if retry.any() and not taken.all():
                    free = np.flatnonzero(~taken)
                    second = self._match(pts[free], self.reference, retry)
                    hit = second >= 0
                    owner[hit] = free[second[hit]]
            else:
                self.rest_frames += 1
                # a marker whose dot is not where it was tracked changed identity: no step this frame
                seen = owner >= 0
                jump = np.zeros(m, dtype=bool)
                jump[seen] = np.linalg.norm(pts[owner[seen]] - self.last[seen], axis=1) > self.gate[seen]
                self.lost |= jump
            found = owner >= 0
            if areas is not None:
                a = np.asarray(areas, dtype=np.float64).reshape(-1)[valid]
                blob = np.where(found, a[np.maximum(owner, 0)], np.nan)
                if self.reference_area is None:
                    self.reference_area = blob  # NaN for markers not seen: never refused
                with np.errstate(invalid="ignore"):
                    merged = found & (blob > self.merge_ratio * self.reference_area)
                found &= ~merged
                owner[merged] = -1
            out[found] = pts[owner[found]]
            self.match = np.where(found, valid[np.maximum(owner, 0)], -1)
        else:
            found = np.zeros(m, dtype=bool)
            self.match = np.full(m, -1, dtype=np.int64)
        step = np.where(found[:, None] & ~self.lost[:, None], out - self.last, np.nan)
        if self.predict:
            self.velocity = np.nan_to_num(step)
        self.last[found] = out[found]
        if (~found).any() and self._neighbours.shape[1]:
            # carry lost markers along with their neighbours' median motion this frame
            lost = np.flatnonzero(~found)
            self.last[lost] += _nanmedian_rows(step[self._neighbours[lost]])
        self.lost = ~found
        return out

    def _at_rest(self, pts: np.ndarray) -> np.ndarray | None:
        """The rest assignment (index into ``pts`` per marker, -1: not seen) if ``pts`` show the grid
        at rest (see the module doc), else None."""
        m = len(self.reference)
        if len(pts) < self.rest_fraction * m or len(pts) > m:
            return None
        dist, j = self._ref_tree.query(pts, k=1, distance_upper_bound=float(self.home.max()))
        if not np.isfinite(dist).all():
            return None
        if (dist > self.home[j]).any():
            return None
        owner = np.full(m, -1, dtype=np.int64)
        owner[j] = np.arange(len(pts))
        if np.count_nonzero(owner >= 0) != len(pts):  # two dots at one home: not the grid at rest
            return None
        return owner

    def _match(self, pts: np.ndarray, guess: np.ndarray, active: np.ndarray,
               claimed: np.ndarray | None = None) -> np.ndarray:
        """Index into ``pts`` for each marker (-1: none within its gate); one marker per point.

        ``claimed`` (K,) bool, if given, is set for every point some marker's guess reached,
        whether it won the point or the point was contested."""
        m = len(guess)
        owner = np.full(m, -1, dtype=np.int64)
        act = np.flatnonzero(active)
        if self.assignment == "optimal":
            return self._match_optimal(pts, guess, act, owner, claimed)
        dist, j = cKDTree(pts).query(guess[act], k=1, distance_upper_bound=float(self.gate.max()))
        ok = np.isfinite(dist) & (dist <= self.gate[act])
        if claimed is not None:
            claimed[j[ok]] = True
        act, dist, j = act[ok], dist[ok], j[ok]
        order = np.lexsort((dist, j))  # by point, closest marker first
        act, dist, j = act[order], dist[order], j[order]
        first = np.ones(len(j), dtype=bool)
        first[1:] = j[1:] != j[:-1]
        # a point claimed twice goes to the closer marker only if clearly closer (else: a merge)
        runner_up = np.full(len(j), np.inf)
        second = np.flatnonzero(~first[1:] & first[:-1]) + 1 if len(j) > 1 else np.zeros(0, int)
        runner_up[second - 1] = dist[second]
        win = first & (dist <= self.ambiguity * runner_up + 1e-9)
        owner[act[win]] = j[win]
        return owner

    def _match_optimal(self, pts: np.ndarray, guess: np.ndarray, act: np.ndarray,
                       owner: np.ndarray, claimed: np.ndarray | None) -> np.ndarray:
        from scipy.optimize import linear_sum_assignment

        gate = self.gate[act]
        d = np.linalg.norm(guess[act, None, :] - pts[None, :, :], axis=2)
        if claimed is not None:
            claimed |= (d <= gate[:, None]).any(axis=0)
        big = 1e6
        cost = np.where(d <= gate[:, None], d, big)
        rows, cols = linear_sum_assignment(cost)
        ok = cost[rows, cols] < big
        owner[act[rows[ok]]] = cols[ok]
        return owner


def _nanmedian_rows(x: np.ndarray) -> np.ndarray:
    """Median over axis 1 ignoring NaN, 0 where all are NaN; (L, K, D) -> (L, D).

    ``np.nanmedian`` loops in Python over small rows; sorting puts NaN last, so
    the median is an index into the sorted valid prefix.
    """
    s = np.sort(x, axis=1)
    count = np.isfinite(x).sum(axis=1)  # (L, D)
    lo = np.clip((count - 1) // 2, 0, None)
    hi = np.clip(count // 2, 0, x.shape[1] - 1)
    lo_v = np.take_along_axis(s, lo[:, None, :], axis=1)[:, 0, :]
    hi_v = np.take_along_axis(s, hi[:, None, :], axis=1)[:, 0, :]
    return np.where(count > 0, 0.5 * (lo_v + hi_v), 0.0)
