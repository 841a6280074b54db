"""``actionDetection``: a small state machine that names what touched the skin.

It looks only at contacts over time (no raw data), so it works the same for
every device family. Each action is emitted once when its condition first holds:

- ``touch`` / ``collision``: the first frame with a contact; collision when the
  deepest node moved faster than ``collision_speed_mm_s`` since the last rest frame.
- ``press``: a contact held for ``press_s`` without slipping.
- ``slip``: the main contact moved tangentially more than ``slip_mm`` from where it
  settled, or its mean shear exceeded ``slip_shear_ratio`` x its mean normal depth.
  It re-arms when the contact comes to rest again.
- ``pinch``: two contacts whose distance shrank by ``pinch_mm`` since both appeared,
  each of them moving towards the other (at least a quarter of ``pinch_mm``). The
  second contact must be a finger, not a ripple: at least ``pinch_peak_ratio`` of
  the main contact's peak, and the same contact from frame to frame (neither
  jumps more than ``pinch_jump_mm``; a jump restarts the count). So a slide under
  shear, whose bulge and edge ripples come and go as small secondary contacts,
  is no pinch (issue 14).
- ``pat``: a touch shorter than ``pat_s`` (emitted just before its ``release``).
- ``release``: the first frame with no contact after a touch.

Each action comes with its evidence (``details``, the ``actionDetails`` event):
the number of contacts, the touch's duration, the main contact's speed, and a
confidence in [0.5, 1]: how clearly the deciding quantity crossed its
threshold (0.5 at the threshold, 1 at twice the margin; touch and release are
certain). It is kept as a few numbers per emitted action and turned into a
payload only when someone listens (``FrameResult.action_details``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .contacts import Contact

__all__ = ["ACTIONS", "ActionDetector", "ActionEvidence", "ActionParams"]

ACTIONS = ("touch", "release", "press", "slip", "pat", "pinch", "collision")


@dataclass(frozen=True, slots=True)
class ActionParams:
    press_s: float = 0.3
    pat_s: float = 0.25
    slip_mm: float = 2.0
    slip_shear_ratio: float = 1.0
    rest_speed_mm_s: float = 5.0
    pinch_mm: float = 3.0
    pinch_peak_ratio: float = 0.3
    pinch_jump_mm: float = 5.0
    collision_speed_mm_s: float = 150.0


@dataclass(frozen=True, slots=True)
class ActionEvidence:
    """One emitted action and what it was taken on (the ``actionDetails`` event's data)."""

    action: str
    confidence: float
    contacts: int
    duration_s: float
    speed_mm_s: float
    moved_mm: float = 0.0
    approach_mm: float = 0.0

    def payload(self) -> dict[str, object]:
        return {"action": self.action, "confidence": round(self.confidence, 3), "evidence": {
            "contacts": self.contacts, "durationS": round(self.duration_s, 4),
            "speedMmPerS": round(self.speed_mm_s, 3), "moveMm": round(self.moved_mm, 3),
            "approachMm": round(self.approach_mm, 3)}}


def _confidence(value: float, threshold: float) -> float:
    """0.5 where ``value`` just crosses ``threshold`` (either way), 1 at twice the margin."""
    if threshold <= 0:
        return 1.0
    return min(1.0, 0.5 + 0.5 * abs(value - threshold) / threshold)


Point = tuple[float, float, float]


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    """|a - b| of two 3-vectors as Python floats: the sum ``(a - b) @ (a - b)`` does for three numbers
    (in order, no fused multiply-add), without a dozen microseconds of array calls a frame."""
    x, y, z = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return math.sqrt(x * x + y * y + z * z)


def _xyz(v: np.ndarray) -> Point:
    x, y, z = v.tolist()
    return x, y, z


_ORIGIN: Point = (0.0, 0.0, 0.0)


def _along(a: Point, b: Point, u: Sequence[float]) -> float:
    """(a - b) @ u, summed in order like the three-number dot product."""
    return (a[0] - b[0]) * u[0] + (a[1] - b[1]) * u[1] + (a[2] - b[2]) * u[2]


class ActionDetector:
    """Feed it each frame's contacts; it returns the actions that frame completes."""

    def __init__(self, params: ActionParams | None = None) -> None:
        self.p = params or ActionParams()
        self._onset_ns: int | None = None
        self._last_rest_ns: int | None = None
        self._prev_ns: int | None = None
        self._anchor: Point | None = None
        self._prev_loc: Point | None = None
        self._still_since: int | None = None
        self._slipping = False
        self._pressed = False
        self._pinch_d0: float | None = None
        self._pinch_start: tuple[Point, Point] | None = None  # both fingers where they appeared
        self._pinch_prev: tuple[Point, Point] | None = None
        self._pinched = False
        self._speed = 0.0
        self._moved = 0.0
        self._approach = 0.0
        self.details: list[ActionEvidence] = []  # the evidence of the actions the last update returned

    def update(self, t_ns: int, contacts: list[Contact]) -> list[str]:
        onset = self._onset_ns
        out = self._update(t_ns, contacts)
        if out:  # rare: a few per touch
            self.details = [self._evidence(a, t_ns, onset, contacts) for a in out]
        elif self.details:
            self.details = []
        return out

    def _evidence(self, action: str, t_ns: int, onset: int | None, contacts: list[Contact]) -> ActionEvidence:
        p = self.p
        start = self._onset_ns if self._onset_ns is not None else onset
        duration = (t_ns - start) / 1e9 if start is not None else 0.0
        conf = {
            "touch": 1.0, "release": 1.0,
            "collision": _confidence(self._speed, p.collision_speed_mm_s),
            "press": _confidence(self._speed, p.rest_speed_mm_s),
            "slip": max(_confidence(self._moved, p.slip_mm), 0.5),
            "pat": _confidence(duration, p.pat_s),
            "pinch": _confidence(self._approach, p.pinch_mm),
        }.get(action, 1.0)
        return ActionEvidence(action, conf, len(contacts), duration, self._speed, self._moved, self._approach)

    def _update(self, t_ns: int, contacts: list[Contact]) -> list[str]:
        p = self.p
        out: list[str] = []
        if not contacts:
            if self._onset_ns is not None:
                if (t_ns - self._onset_ns) / 1e9 < p.pat_s and not self._pressed:
                    out.append("pat")
                out.append("release")
                self._reset()
            self._last_rest_ns = t_ns
            self._prev_ns = t_ns
            return out

        main = contacts[0]
        if self._onset_ns is None:
            self._onset_ns = t_ns
            dt = (t_ns - self._last_rest_ns) / 1e9 if self._last_rest_ns is not None else None
            self._speed = main.peak / dt if dt is not None and dt > 0 else 0.0
            fast = self._speed > p.collision_speed_mm_s
            out.append("collision" if fast else "touch")
            self._anchor = self._prev_loc = _xyz(main.location)
            self._still_since = t_ns
        else:
            assert self._prev_loc is not None and self._anchor is not None  # set at the touch
            loc = _xyz(main.location)
            dt = max((t_ns - (self._prev_ns or t_ns)) / 1e9, 1e-9)
            speed = self._speed = _dist(loc, self._prev_loc) / dt
            if speed > p.rest_speed_mm_s:
                self._still_since = None
            elif self._still_since is None:
                self._still_since = t_ns
            moved = self._moved = _dist(loc, self._anchor)
            sheared = _dist(_xyz(main.shear), _ORIGIN) > p.slip_shear_ratio * max(main.depth, 1e-9)
            if not self._slipping and (moved > p.slip_mm or sheared):
                out.append("slip")
                self._slipping = True
            if self._slipping and self._still_since is not None and (
                (t_ns - self._still_since) / 1e9 >= p.press_s
            ):
                self._slipping = False  # settled again: a new slide is a new slip
                self._anchor = loc
            if (
                not self._pressed
                and not self._slipping
                and (t_ns - self._onset_ns) / 1e9 >= p.press_s
            ):
                out.append("press")
                self._pressed = True
            self._prev_loc = loc
        self._update_pinch(contacts, out)
        self._prev_ns = t_ns
        return out

    def _update_pinch(self, contacts: list[Contact], out: list[str]) -> None:
        p = self.p
        if len(contacts) < 2 or contacts[1].peak < p.pinch_peak_ratio * contacts[0].peak:
            self._pinch_d0 = self._pinch_start = self._pinch_prev = None
            return
        a, b = _xyz(contacts[0].location), _xyz(contacts[1].location)
        prev = self._pinch_prev
        if prev is not None:
            if _dist(a, prev[1]) + _dist(b, prev[0]) < _dist(a, prev[0]) + _dist(b, prev[1]):
                a, b = b, a  # the same two fingers, listed the other way round
            if max(_dist(a, prev[0]), _dist(b, prev[1])) > p.pinch_jump_mm:
                prev = None  # another contact took a finger's place: a new pair
        self._pinch_prev = (a, b)
        d = _dist(a, b)
        if prev is None or self._pinch_d0 is None or self._pinch_start is None:
            self._pinch_d0, self._pinch_start = d, (a, b)
            return
        if self._pinched or self._pinch_d0 - d <= p.pinch_mm:
            return
        a0, b0 = self._pinch_start
        scale = max(self._pinch_d0, 1e-9)
        u = [(b0[i] - a0[i]) / scale for i in range(3)]
        if (_along(a, a0, u) >= p.pinch_mm / 4 and _along(b0, b, u) >= p.pinch_mm / 4):
            self._approach = self._pinch_d0 - d
            out.append("pinch")
            self._pinched = True

    def _reset(self) -> None:
        self._onset_ns = None
        self._anchor = self._prev_loc = self._still_since = None
        self._slipping = self._pressed = self._pinched = False
        self._pinch_d0 = self._pinch_start = self._pinch_prev = None
        self._moved = self._approach = 0.0
