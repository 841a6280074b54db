"""``actionDetection``: a small state machine that names what touched the skin.

It looks only at contacts over time (no raw data), so it works the same for
every device family. Each action is emitted once when its condition first holds:

- ``touch`` / ``collision``: the first frame with a contact; collision when the
  deepest node moved faster than ``collision_speed_mm_s`` since the last rest frame.
- ``press``: a contact held for ``press_s`` without slipping.
- ``slip``: the main contact moved tangentially more than ``slip_mm`` from where it
  settled, or its mean shear exceeded ``slip_shear_ratio`` x its mean normal depth.
  It re-arms when the contact comes to rest again.
- ``pinch``: two contacts whose distance shrank by ``pinch_mm`` since both appeared.
- ``pat``: a touch shorter than ``pat_s`` (emitted just before its ``release``).
- ``release``: the first frame with no contact after a touch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .contacts import Contact

__all__ = ["ACTIONS", "ActionDetector", "ActionParams"]

ACTIONS = ("touch", "release", "press", "slip", "pat", "pinch", "collision")


@dataclass(frozen=True, slots=True)
class ActionParams:
    press_s: float = 0.3
    pat_s: float = 0.25
    slip_mm: float = 2.0
    slip_shear_ratio: float = 1.0
    rest_speed_mm_s: float = 5.0
    pinch_mm: float = 3.0
    collision_speed_mm_s: float = 150.0


def _norm(v: np.ndarray) -> float:
    """Length of a 3-vector: np.linalg.norm's generality costs more than the sum itself here."""
    return math.sqrt(float(v @ v))


class ActionDetector:
    """Feed it each frame's contacts; it returns the actions that frame completes."""

    def __init__(self, params: ActionParams | None = None) -> None:
        self.p = params or ActionParams()
        self._onset_ns: int | None = None
        self._last_rest_ns: int | None = None
        self._prev_ns: int | None = None
        self._anchor: np.ndarray | None = None
        self._prev_loc: np.ndarray | None = None
        self._still_since: int | None = None
        self._slipping = False
        self._pressed = False
        self._pinch_d0: float | None = None
        self._pinched = False

    def update(self, t_ns: int, contacts: list[Contact]) -> list[str]:
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
            fast = dt is not None and dt > 0 and main.peak / dt > p.collision_speed_mm_s
            out.append("collision" if fast else "touch")
            self._anchor = self._prev_loc = main.location
            self._still_since = t_ns
        else:
            dt = max((t_ns - (self._prev_ns or t_ns)) / 1e9, 1e-9)
            speed = _norm(main.location - self._prev_loc) / dt
            if speed > p.rest_speed_mm_s:
                self._still_since = None
            elif self._still_since is None:
                self._still_since = t_ns
            moved = _norm(main.location - self._anchor)
            sheared = _norm(main.shear) > p.slip_shear_ratio * max(main.depth, 1e-9)
            if not self._slipping and (moved > p.slip_mm or sheared):
                out.append("slip")
                self._slipping = True
            if self._slipping and self._still_since is not None and (
                (t_ns - self._still_since) / 1e9 >= p.press_s
            ):
                self._slipping = False  # settled again: a new slide is a new slip
                self._anchor = main.location
            if (
                not self._pressed
                and not self._slipping
                and (t_ns - self._onset_ns) / 1e9 >= p.press_s
            ):
                out.append("press")
                self._pressed = True
            self._prev_loc = main.location
        self._update_pinch(contacts, out)
        self._prev_ns = t_ns
        return out

    def _update_pinch(self, contacts: list[Contact], out: list[str]) -> None:
        if len(contacts) < 2:
            self._pinch_d0 = None
            return
        d = _norm(contacts[0].location - contacts[1].location)
        if self._pinch_d0 is None:
            self._pinch_d0 = d
        elif not self._pinched and self._pinch_d0 - d > self.p.pinch_mm:
            out.append("pinch")
            self._pinched = True

    def _reset(self) -> None:
        self._onset_ns = None
        self._anchor = self._prev_loc = self._still_since = None
        self._slipping = self._pressed = self._pinched = False
        self._pinch_d0 = None
