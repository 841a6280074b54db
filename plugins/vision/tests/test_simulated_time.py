"""A simulated camera read late stamps each frame with the instant it was due, not when it was read
(issue 48, item 9): a busy reader skips frames, and the ones it gets keep their own times, so what
is derived from them (speeds, a press's duration) is what the scene did."""

from __future__ import annotations

import time

import numpy as np
from wott_vision.simulated import SimulatedSource

from wott_hub.plugin_api import Scene


class _Still:
    """A simulator that renders nothing: only the source's timing is looked at."""

    def __init__(self) -> None:
        self.scene = Scene.from_dict({"scene": {"loop": True}, "step": [
            {"kind": "press", "at": [0.0, 0.0, 0.0], "start_s": 0.0, "duration_s": 0.5, "depth_mm": 1.0,
             "radius_mm": 3.0}]})

    def render(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((4, 4), np.uint8), np.zeros((1, 3))


def test_a_late_read_skips_frames_and_stamps_the_one_it_gets_with_its_due_time():
    src = SimulatedSource(_Still(), 20.0, realtime=True)
    stamps = []
    for pause in (0.0, 0.0, 0.16, 0.0, 0.3, 0.0):  # late by three frames, then by six
        time.sleep(pause)
        ok, _ = src.read()
        assert ok and src.captured_s is not None
        stamps.append((src.t_s, src.captured_s))
    t0, c0 = stamps[0]
    for t_s, captured_s in stamps:  # the stamp is the scene time's instant, however late the read
        assert abs((captured_s - c0) - (t_s - t0)) < 1e-9
    ks = [round(t_s * 20.0) for t_s, _ in stamps]
    assert ks == sorted(set(ks)) and ks[-1] >= 10  # frames skipped (never repeated), time kept
    assert src.frames_read == 6


def test_a_source_not_paced_has_no_capture_time():
    src = SimulatedSource(_Still(), 20.0, realtime=False)
    assert src.read()[0] and src.captured_s is None and src.t_s == 0.0
