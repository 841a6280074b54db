"""``actionDetection``: a small state machine that names what touched the skin, finger by finger.

It looks only at tracked contacts over time (``tracking.ContactTracker`` gives each
finger its id), so it works the same for every device family, and a finger's motion
is its own: two fingers that swap places in a ranking by size do not make one
finger jump. Times are the frames' own (the device's clock, not the arrival of the
frame), and every speed is a least-squares line through the finger's held positions
of the last ``speed_window_s`` of frame time (0.4 s: twelve frames of a 30 frames/s
camera, whose location moves in steps of its marker grid), never a difference over
one frame interval nor a count of frames. So a frame that is skipped (dropped by a
busy reader, lost on the line) or that arrives late changes nothing that is derived:
every duration is a difference of frame times, the press window's start is the
finger's position interpolated at that instant between the held frames either side
of it, and a speed's window is a span of time, however many frames fell in it.
Each action is emitted once when its condition first holds:

- ``touch`` / ``collision``: the first frame with a contact; collision when the
  deepest node moved faster than ``collision_speed_mm_s`` since the last rest frame.
- ``press``: the touch has lasted ``press_s``, no finger is slipping and every
  finger is still: over the last ``press_s`` (from its position interpolated at
  that instant) it moved less than half its slip distance.
- ``slip``: a finger moved more than its slip distance from where it settled, or
  its mean shear exceeded ``slip_shear_ratio`` x its mean normal depth, in two
  held frames in a row (a camera estimate's location can jump once). The slip
  distance is ``slip_mm`` or ``slip_size_ratio`` of the contact's radius, the
  larger (a wide contact's centre wanders more as it is pressed). Motion is
  judged only while the finger is *held*, its peak at least ``hold_ratio`` of its
  own deepest, so a contact shrinking away as it lifts (a camera estimate's centre
  drifts then) is no slip; while its peak grows by a quarter the place it settles
  follows it (the press is still coming in). It re-arms when the finger is still
  again for ``press_s``.
- ``pinch``: two fingers (each at least ``pinch_peak_ratio`` of the strongest peak)
  whose distance shrank by ``pinch_mm`` since both were there, each of them moving
  towards the other (at least a quarter of ``pinch_mm``). Their motion is the
  pinch: it makes no slip.
- ``pat``: a touch shorter than ``pat_s`` that was no press (emitted before ``release``).
- ``release``: the first frame with no contact after a touch; its speed is the
  first finger's over its last held frames (how fast it was moving as it lifted).

Each action comes with its evidence (``details``, the ``actionDetails`` event):
the number of contacts, the touch's duration, the deciding finger's id and speed,
how far it moved, and a confidence in [0.5, 1]: how clearly the deciding quantity
crossed its threshold (0.5 at the threshold, 1 at twice the margin; touch and
release are certain). It is kept as a few numbers per emitted action and turned
into a payload only when someone listens (``FrameResult.action_details``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from .contacts import Contact

__all__ = ["ACTIONS", "ActionDetector", "ActionEvidence", "ActionParams"]

ACTIONS = ("touch", "release", "press", "slip", "pat", "pinch", "collision")

Point = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class ActionParams:
    press_s: float = 0.3
    pat_s: float = 0.25
    slip_mm: float = 2.0
    slip_size_ratio: float = 0.25
    slip_shear_ratio: float = 1.0
    hold_ratio: float = 0.5
    speed_window_s: float = 0.4
    pinch_mm: float = 3.0
    pinch_peak_ratio: float = 0.3
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
    contact_id: int = 0  # the finger it was decided on (0: the whole touch)

    def payload(self) -> dict[str, object]:
        evidence: dict[str, object] = {
            "contacts": self.contacts, "durationS": round(self.duration_s, 4),
            "speedMmPerS": round(self.speed_mm_s, 3), "moveMm": round(self.moved_mm, 3),
            "approachMm": round(self.approach_mm, 3)}
        if self.contact_id:
            evidence["contactId"] = self.contact_id
        return {"action": self.action, "confidence": round(self.confidence, 3), "evidence": evidence}


def _confidence(value: float, threshold: float) -> float:
    """0.5 where ``value`` just crosses ``threshold`` (either way), 1 at twice the margin."""
    if threshold <= 0:
        return 1.0
    return min(1.0, 0.5 + 0.5 * abs(value - threshold) / threshold)


def _dist(a: Point, b: Point) -> float:
    x, y, z = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    return math.sqrt(x * x + y * y + z * z)


def _along(a: Point, b: Point, u: Point) -> float:
    """(a - b) @ u."""
    return (a[0] - b[0]) * u[0] + (a[1] - b[1]) * u[1] + (a[2] - b[2]) * u[2]


class _Finger:
    """One tracked contact's motion: where it settled, its held positions over the last window.

    ``moved``: from where it settled; ``travel``: over the last ``press_s`` of held
    frames (or since it was first held); ``slip_mm``: its slip distance (by its size);
    ``sheared``: its mean shear beyond the slip ratio. Set by ``ActionDetector._follow``.
    """

    __slots__ = ("anchor", "anchor_peak", "id", "loc", "max_peak", "moved", "origin", "over", "pinched",
                 "roam", "samples", "sheared", "slip_mm", "slipping", "still", "travel")

    def __init__(self, c: Contact, loc: Point) -> None:
        self.id = c.id
        self.loc = self.anchor = self.origin = loc
        self.roam = 0.0  # the farthest it has been from where it was first seen, mm
        self.anchor_peak = self.max_peak = c.peak
        self.samples: deque[tuple[int, Point]] = deque()  # (t_ns, location) of held frames, oldest first
        self.moved = self.travel = self.slip_mm = 0.0
        self.over = 0  # held frames in a row beyond the slip distance (or sheared)
        self.slipping = self.pinched = self.sheared = False
        self.still = True

    def speed(self, window_s: float) -> float:
        """mm/s over the held frames of the last ``window_s`` of frame time (the last two if fewer
        fell in it): the slope of a least-squares line through their positions (a camera skin's
        location moves by steps of its marker grid, a line through several frames follows the
        finger, not the steps). A window of time, not of frames: frames skipped in it leave the
        slope as it was."""
        samples = self.samples
        if len(samples) < 2:
            return 0.0
        end = samples[-1][0]
        edge = end - int(window_s * 1e9)
        recent = [s for s in samples if s[0] >= edge]
        if len(recent) < 2:
            recent = list(samples)[-2:]
        ts = [(t - end) / 1e9 for t, _ in recent]
        mean_t = sum(ts) / len(ts)
        var = sum((t - mean_t) ** 2 for t in ts)
        if var <= 0:
            return 0.0
        v = [sum((t - mean_t) * loc[i] for t, (_, loc) in zip(ts, recent, strict=True)) / var
             for i in range(3)]
        return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


class ActionDetector:
    """Feed it each frame's tracked contacts; it returns the actions that frame completes."""

    def __init__(self, params: ActionParams | None = None) -> None:
        self.p = p = params or ActionParams()
        self._horizon_ns = int(max(p.press_s, p.speed_window_s) * 1e9)  # the held positions kept
        self._press_ns = p.press_s * 1e9
        self._hold, self._slip_mm, self._shear_k = p.hold_ratio, p.slip_mm, p.slip_shear_ratio
        self._size_k = p.slip_size_ratio / math.sqrt(math.pi)  # x sqrt(area): x the contact's radius
        self._onset_ns: int | None = None
        self._last_rest_ns: int | None = None
        self._fingers: dict[int, _Finger] = {}
        self._pairs: dict[tuple[int, int], tuple[float, Point, Point]] = {}  # both ids -> (d0, a0, b0)
        self._pressed = self._pinched = False
        self._last: _Finger | None = None  # the first finger of the last touched frame
        self.details: list[ActionEvidence] = []  # the evidence of the actions the last update returned

    def update(self, t_ns: int, contacts: list[Contact]) -> list[str]:
        onset = self._onset_ns
        out: list[str] = []
        ev: list[ActionEvidence] = []
        if not contacts:
            if onset is not None:
                duration = (t_ns - onset) / 1e9
                last = self._last
                speed = self._speed(last) if last is not None else 0.0
                fid = last.id if last is not None else 0
                if duration < self.p.pat_s and not self._pressed:
                    out.append("pat")
                    ev.append(ActionEvidence("pat", _confidence(duration, self.p.pat_s), 0, duration, speed,
                                             contact_id=fid))
                out.append("release")
                ev.append(ActionEvidence("release", 1.0, 0, duration, speed, contact_id=fid))
                self._reset()
            self._last_rest_ns = t_ns
        else:
            self._touched(t_ns, contacts, out, ev)
        self.details = ev
        return out

    def _follow(self, t_ns: int, c: Contact, f: _Finger) -> bool:
        """Take this frame's contact into its finger's motion; True while it is held (motion judged)."""
        x, y, z = loc = c.xyz
        f.loc = loc
        ox, oy, oz = f.origin
        roam = (x - ox) ** 2 + (y - oy) ** 2 + (z - oz) ** 2
        if roam > f.roam * f.roam:
            f.roam = math.sqrt(roam)
        peak = c.peak
        if peak > f.max_peak:
            f.max_peak = peak
        if peak > 1.25 * f.anchor_peak:  # still pressing in: it settles further on
            f.anchor, f.anchor_peak = loc, peak
        if peak < self._hold * f.max_peak:
            return False
        samples = f.samples
        samples.append((t_ns, loc))
        horizon = t_ns - self._horizon_ns
        while len(samples) > 2 and samples[1][0] <= horizon:  # one at or before the horizon stays
            samples.popleft()
        slip = f.slip_mm = max(self._slip_mm, self._size_k * math.sqrt(c.area))
        ax, ay, az = f.anchor
        f.moved = math.sqrt((x - ax) ** 2 + (y - ay) ** 2 + (z - az) ** 2)
        sx, sy, sz = self._press_start(samples, t_ns - self._press_ns)
        travel = f.travel = math.sqrt((x - sx) ** 2 + (y - sy) ** 2 + (z - sz) ** 2)
        f.still = travel < 0.5 * slip
        if not f.slipping and not f.pinched:
            hx, hy, hz = c.shear.tolist()
            f.sheared = hx * hx + hy * hy + hz * hz > (self._shear_k * max(c.depth, 1e-9)) ** 2
            f.over = f.over + 1 if f.moved > slip or f.sheared else 0
        return True

    @staticmethod
    def _press_start(samples: deque[tuple[int, Point]], edge_ns: float) -> Point:
        """Where the finger was ``press_s`` ago: interpolated in frame time between the held frames
        either side of that instant (so a frame skipped there does not shorten the window), or
        where it was first held if that is later."""
        t0, a = samples[0]
        if t0 >= edge_ns:
            return a
        for t1, b in samples:
            if t1 >= edge_ns:
                w = (edge_ns - t0) / (t1 - t0)
                return (a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2]))
            t0, a = t1, b
        return a

    def _touched(self, t_ns: int, contacts: list[Contact], out: list[str], ev: list[ActionEvidence]) -> None:
        p = self.p
        n = len(contacts)
        if self._onset_ns is None:
            self._onset_ns = t_ns
            rest = self._last_rest_ns
            dt = (t_ns - rest) / 1e9 if rest is not None else 0.0
            speed = contacts[0].peak / dt if dt > 0 else 0.0
            action = "collision" if speed > p.collision_speed_mm_s else "touch"
            conf = _confidence(speed, p.collision_speed_mm_s) if action == "collision" else 1.0
            out.append(action)
            ev.append(ActionEvidence(action, conf, n, 0.0, speed, contact_id=contacts[0].id))
        duration = (t_ns - self._onset_ns) / 1e9
        fingers = self._fingers
        if n == 1 and len(fingers) == 1 and contacts[0].id in fingers:  # one finger, as before: no new dict
            f = fingers[contacts[0].id]
            held = [f] if self._follow(t_ns, contacts[0], f) else []
        else:
            present: dict[int, _Finger] = {}
            held = []
            new: list[_Finger] = []
            for c in contacts:
                known = fingers.get(c.id)
                if known is None:
                    known = _Finger(c, c.xyz)
                    new.append(known)
                if self._follow(t_ns, c, known):
                    held.append(known)
                present[c.id] = known
            self._fingers = fingers = present
            for f in new:
                self._pair_up(f)
        first = self._last = fingers[min(fingers)]
        if n > 1 and not self._pinched:
            self._update_pinch(contacts, duration, out, ev)
        for f in held:
            if not f.slipping:
                if not f.pinched and f.over >= 2:
                    f.slipping = True
                    if "slip" not in out:
                        out.append("slip")
                        conf = max(_confidence(f.moved, f.slip_mm), 0.5)
                        ev.append(ActionEvidence("slip", conf, n, duration, self._speed(f),
                                                 f.moved, contact_id=f.id))
            elif f.still and t_ns - f.samples[0][0] >= self._press_ns:
                f.slipping, f.anchor = False, f.loc  # settled again: a new slide is a new slip
        if not self._pressed and held and duration >= p.press_s:
            if all(f.still and not f.slipping for f in fingers.values()):
                self._pressed = True
                out.append("press")
                worst = max(held, key=lambda f: f.travel / f.slip_mm)
                ev.append(ActionEvidence("press", _confidence(worst.travel, 0.5 * worst.slip_mm), n, duration,
                                         self._speed(worst), worst.travel, contact_id=first.id))

    def _pair_up(self, f: _Finger) -> None:
        """``f`` is first seen now: its pairs with the fingers there start here (the pinch)."""
        pairs = self._pairs
        for g in self._fingers.values():
            key = (g.id, f.id) if g.id < f.id else (f.id, g.id)
            if g is not f and key not in pairs:
                fa, fb = (g, f) if g.id < f.id else (f, g)
                pairs[key] = (_dist(fa.loc, fb.loc), fa.loc, fb.loc)

    def _update_pinch(self, contacts: list[Contact], duration: float, out: list[str],
                      ev: list[ActionEvidence]) -> None:
        """A pair that formed when its second finger came, both fingers each still a finger (not a
        ripple beside a stronger one) and each having moved: only a finger that roamed a quarter of
        ``pinch_mm`` from where it was first seen can have moved that far towards another since
        (ten still fingers cost ten comparisons, not 45 pair tests)."""
        p = self.p
        strongest = max(c.peak for c in contacts)
        reach = p.pinch_mm / 8
        fingers = sorted((self._fingers[c.id] for c in contacts
                          if c.peak >= p.pinch_peak_ratio * strongest and self._fingers[c.id].roam >= reach),
                         key=lambda f: f.id)
        pairs = self._pairs
        for i, fa in enumerate(fingers):
            for fb in fingers[i + 1:]:
                start = pairs.get((fa.id, fb.id))
                if start is None:
                    continue
                d0, a0, b0 = start
                approach = d0 - _dist(fa.loc, fb.loc)
                if approach <= p.pinch_mm:
                    continue
                scale = max(d0, 1e-9)
                u = ((b0[0] - a0[0]) / scale, (b0[1] - a0[1]) / scale, (b0[2] - a0[2]) / scale)
                if _along(fa.loc, a0, u) >= p.pinch_mm / 4 and _along(b0, fb.loc, u) >= p.pinch_mm / 4:
                    self._pinched = fa.pinched = fb.pinched = True
                    out.append("pinch")
                    speed = (self._speed(fa) + self._speed(fb)) / 2
                    ev.append(ActionEvidence("pinch", _confidence(approach, p.pinch_mm), len(contacts),
                                             duration, speed, 0.0, approach, fa.id))
                    return

    def _speed(self, f: _Finger) -> float:
        return f.speed(self.p.speed_window_s)

    def _reset(self) -> None:
        self._onset_ns = None
        self._fingers = {}
        self._pairs = {}
        self._pressed = self._pinched = False
        self._last = None
