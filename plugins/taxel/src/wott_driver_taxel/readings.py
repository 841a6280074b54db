"""A taxel array's readings as the hub's frames: what its counts mean, and what ``tare`` takes again.

Two meanings. A calibrated array (the project's own binary and ASCII protocols): 16-bit counts of
pressure, through the skin's compliance into an inward displacement in mm (``Compliance``); ``tare``
makes the next frame every taxel's zero. An uncalibrated matrix (FlexiTac, 3D-ViTac): 8-bit ADC
counts with no known pressure, so its node vectors are the counts above a baseline along the inward
normal (``taxelSignal``, counts), never a displacement; the baseline is the per-taxel median of the
first ``baseline_frames`` frames (30, as both makers' readers take it), and ``tare`` takes it again
from the next ones while the old one stays in use. While the first baseline is being taken no frame
comes out (``baseline_progress``). Both serve the last frame's grids as raw signals.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from wott_hub.plugin_api import RawSample, RawSignal, TactileFrame

from .compliance import Compliance

__all__ = ["CountReadings", "PressureReadings", "Readings"]

class Readings(Protocol):
    raw_signals: tuple[RawSignal, ...]

    def frame(self, t_ns: int, counts: np.ndarray) -> TactileFrame | None: ...

    def tare(self) -> str: ...

    def raw_sample(self, name: str) -> RawSample | None: ...


class PressureReadings:
    """Counts -> kPa -> inward displacement (mm) through ``compliance``; the grid ``pressure`` in kPa."""

    def __init__(self, compliance: Compliance, inward: np.ndarray, shape: tuple[int, int],
                 rate_hz: float, record_hz: float = 0.0) -> None:
        self.compliance = compliance
        self.shape = shape
        self._inward = inward
        self.zero: np.ndarray | None = None  # counts at rest after a tare, subtracted from every frame
        self._tare_next = False
        self._pressure: tuple[int, np.ndarray] | None = None  # the last frame's (t_ns, kPa per taxel)
        self.raw_signals: tuple[RawSignal, ...] = (RawSignal("pressure", "grid", shape, unit="kPa",
                                                             rate_hz=rate_hz, record_hz=record_hz),)

    def frame(self, t_ns: int, counts: np.ndarray) -> TactileFrame:
        values = counts.astype(np.float64)
        if self._tare_next:  # this frame's readings are the new zero
            self.zero, self._tare_next = values.copy(), False
        if self.zero is not None:
            values = np.maximum(values - self.zero, 0.0)
        c = self.compliance
        pressure = c.pressure_kpa(values)  # float64: the frame keeps this very array
        self._pressure = (t_ns, pressure)
        return TactileFrame(t_ns, c.normal_mm(values)[:, None] * self._inward, pressure=pressure)

    def tare(self) -> str:
        self._tare_next = True
        return "the next frame's readings are each taxel's new zero"

    def raw_sample(self, name: str) -> RawSample | None:
        """The pressure grid of the last frame, rows x cols kPa (a view of the frame's array)."""
        last = self._pressure
        if name != "pressure" or last is None:
            return None
        return RawSample(last[0], last[1].reshape(self.shape))


class CountReadings:
    """Counts above a per-taxel baseline along the inward normal; grids ``raw`` and ``change`` (counts)."""

    def __init__(self, inward: np.ndarray, shape: tuple[int, int], rate_hz: float,
                 baseline_frames: int, record_hz: float = 0.0) -> None:
        if baseline_frames < 1:
            raise ValueError(f"baseline_frames must be at least 1, got {baseline_frames}")
        self.shape = shape
        self.baseline_frames = baseline_frames
        self.baseline: np.ndarray | None = None
        self._inward = inward
        self._taking: list[np.ndarray] = []  # the frames of the baseline being taken
        self._collecting = True
        self._last: tuple[int, np.ndarray, np.ndarray] | None = None  # (t_ns, raw, change)
        self.raw_signals: tuple[RawSignal, ...] = (
            RawSignal("raw", "grid", shape, unit="count", rate_hz=rate_hz, record_hz=record_hz),
            RawSignal("change", "grid", shape, unit="count", rate_hz=rate_hz))  # recorded: the counts as read

    @property
    def baseline_progress(self) -> str:
        """"" once a baseline is in use, else how far the first one is."""
        if self.baseline is not None:
            return ""
        return f"taking the baseline: {len(self._taking)}/{self.baseline_frames} frames"

    def frame(self, t_ns: int, counts: np.ndarray) -> TactileFrame | None:
        raw = counts.astype(np.float64)
        if self._collecting:
            self._taking.append(raw)
            if len(self._taking) == self.baseline_frames:
                self.baseline = np.median(np.stack(self._taking), axis=0)
                self._taking, self._collecting = [], False
        if self.baseline is None:
            return None
        change = raw - self.baseline
        self._last = (t_ns, raw, change)
        return TactileFrame(t_ns, np.maximum(change, 0.0)[:, None] * self._inward)

    def tare(self) -> str:
        self._taking, self._collecting = [], True
        return f"the median of the next {self.baseline_frames} frames becomes each taxel's baseline"

    def raw_sample(self, name: str) -> RawSample | None:
        """The last frame's counts as read (``raw``) or less the baseline (``change``), rows x cols."""
        last = self._last
        if last is None or name not in ("raw", "change"):
            return None
        return RawSample(last[0], (last[1] if name == "raw" else last[2]).reshape(self.shape))
