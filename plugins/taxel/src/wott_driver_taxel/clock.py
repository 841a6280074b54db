"""Frame times from the board's own cadence, not from when the bytes happened to arrive.

A serial reader sees frames when the OS hands it bytes: several frames in one read
share one arrival time, and a busy hub reads late, so arrival intervals at a nominal
10 ms range from 0 to 30 ms and more. Speeds taken over such stamps are noise. But the
board sends frame ``n`` at ``t0 + n * period`` on its own clock, and every frame
carries ``n`` (its sequence number; the ASCII variant without one is counted). So
each frame's time is that line, fitted to the arrivals: the period is the
least-squares slope of arrival time against ``n`` over the last ``window`` frames
(the configured rate until ``min_fit`` frames spanning ``min_span_s`` are in, or
the raw arrival times when there is no configured rate), and the line is moved down
to the earliest arrival it explains (an arrival is never early; the least delayed
frames show where the line is), so a stamp is at most its frame's arrival once
settled, and always later than the stamp before it. A sequence number that goes
back (the board restarted) starts a new line; a forward jump (frames lost on the
line) just skips ahead on it. When the line moves (a less delayed frame, a refit), the stamps slew to
it: consecutive stamps stay within 10 % of the frames' distance on the line.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .protocol import SEQ_MODULO

__all__ = ["FrameClock"]


class FrameClock:
    """``stamp(seq, arrival_ns)`` -> the frame's time on the hub's clock, in ns.

    The line is refitted every ``refit`` frames (a fit over the window costs tens of
    microseconds); in between, a new arrival can only move it down. Stamps follow the
    line but step by at most ``slew`` of a period more or less than the frames they
    are apart: a refit or an earlier arrival moves the stamps to the new line over a
    few frames, never by a jump a speed would see.
    """

    def __init__(self, period_s: float | None = None, *, window: int = 512, min_fit: int = 16,
                 min_span_s: float = 0.1, refit: int = 16, slew: float = 0.1) -> None:
        if period_s is not None and not period_s > 0:
            raise ValueError(f"period must be positive, got {period_s}")
        self.nominal_ns = None if period_s is None else period_s * 1e9
        self.min_fit, self.min_span_ns, self.refit, self.slew = min_fit, min_span_s * 1e9, refit, slew
        self._points: deque[tuple[int, int]] = deque(maxlen=window)  # (n, arrival - origin ns)
        self._seq: int | None = None
        self._n = 0
        self._origin = 0  # the line's first arrival: every time of the line is relative to it (exact floats)
        self._last = -1  # the last stamp given, on any line
        self._last_n: int | None = None  # its n, on this line
        self._period: float | None = self.nominal_ns
        self._offset: float | None = None
        self._since_fit = 0

    @property
    def period_s(self) -> float | None:
        """The period the stamps follow now (None: raw arrival times, nothing fitted or configured yet)."""
        return None if self._period is None else self._period / 1e9

    def reset(self) -> None:
        """A new line from the next frame (a new stream: the board may have restarted)."""
        self._points.clear()
        self._seq, self._n, self._last_n = None, 0, None
        self._period, self._offset, self._since_fit = self.nominal_ns, None, 0

    def stamp(self, seq: int | None, arrival_ns: int) -> int:
        self._advance(seq)
        n = self._n
        if not self._points:
            self._origin = arrival_ns
        self._points.append((n, arrival_ns - self._origin))
        self._since_fit += 1
        if self._since_fit >= self.refit or self._offset is None:
            self._fit()
        period, offset = self._period, self._offset
        last, last_n = self._last, self._last_n
        if period is None or offset is None:
            t = arrival_ns
        else:
            offset = self._offset = min(offset, arrival_ns - self._origin - period * n)
            t = self._origin + int(round(offset + period * n))
            if last_n is not None:  # on the line, but slewed: no jump between consecutive stamps
                step = period * (n - last_n)
                t = min(max(t, last + int(step * (1 - self.slew))), last + int(step * (1 + self.slew)))
        if t <= last:
            t = last + 1
        self._last, self._last_n = t, n
        return t

    def _advance(self, seq: int | None) -> None:
        if seq is None:  # no sequence number on the line: every frame is the next one
            if self._points:
                self._n += 1
            return
        seq %= SEQ_MODULO
        if self._seq is not None:
            step = (seq - self._seq) % SEQ_MODULO
            if 0 < step < SEQ_MODULO // 2:
                self._n += step
            else:  # a repeat or a step back: the board restarted its count
                self.reset()
        self._seq = seq

    def _fit(self) -> None:
        """The period (least-squares slope of arrival against n, once there is enough to fit) and
        the line's offset (the earliest arrival it explains), over the window."""
        self._since_fit = 0
        pts = np.array(self._points, dtype=np.float64)
        n, a = pts[:, 0], pts[:, 1]
        period = self.nominal_ns
        if len(pts) >= self.min_fit and a[-1] - a[0] >= self.min_span_ns and n[-1] > n[0]:
            dn = n - n.mean()
            slope = float(dn @ (a - a.mean()) / (dn @ dn))
            if slope > 0:
                period = slope
        self._period = period
        self._offset = None if period is None else float(np.min(a - period * n))
