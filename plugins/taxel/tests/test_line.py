"""The simulated serial line on a busy machine (issue 48, item 9): a writer thread that wakes up late
sends the ticks it missed, each made for its own ``k``, instead of skipping scene time; only a stall
longer than ``catch_up_s`` skips ticks, and those are counted. The simulator numbers frame ``k`` by
``k``, so a skipped tick is a gap in the sequence numbers (frames lost on the line), never scene time
squeezed into fewer numbers."""

from __future__ import annotations

import threading
import time

import numpy as np
from wott_driver_taxel.compliance import Compliance
from wott_driver_taxel.line import SimulatedLine
from wott_driver_taxel.pty_port import PtyPort
from wott_driver_taxel.simulator import TaxelSimulator

from wott_hub.plugin_api import Scene, flat_pad


def _run_line(catch_up_s: float, stall_s: float) -> tuple[list[int], SimulatedLine]:
    """100 Hz; the writer stalls ``stall_s`` while making frame 5; the ticks it made, in order."""
    made: list[int] = []
    done = threading.Event()

    def make(k: int) -> bytes:
        made.append(k)
        if k == 5:
            time.sleep(stall_s)  # the machine is busy: this thread gets no core for a while
        if len(made) >= 30:
            done.set()
        return b"x"

    line = SimulatedLine(PtyPort(), 100.0, make, catch_up_s=catch_up_s)
    line.start()
    try:
        assert done.wait(60)
    finally:
        line.stop()
    return made, line


def test_a_late_writer_sends_the_ticks_it_missed():
    made, line = _run_line(catch_up_s=1.0, stall_s=0.2)
    assert made[:30] == list(range(30))  # every tick, in order: 20 of them sent late, as a burst
    assert line.ticks_skipped == 0


def test_a_writer_stalled_beyond_catch_up_s_skips_time_and_counts_it():
    made, line = _run_line(catch_up_s=0.05, stall_s=0.3)
    assert made[:6] == list(range(6)) and made[6] - made[5] > 1  # ticks skipped after the stall...
    gaps = [b - a - 1 for a, b in zip(made, made[1:], strict=False)]
    assert min(gaps) >= 0 and line.ticks_skipped == sum(gaps)  # ...in order, and every one counted


def test_the_simulator_numbers_frame_k_by_k_so_skipped_ticks_are_a_gap():
    mesh = flat_pad(4, 4, pitch_mm=4.0)
    scene = Scene.from_dict({"step": [{"kind": "press", "at": [6.0, 6.0, 0.0], "start_s": 0.0,
                                       "duration_s": 1.0, "depth_mm": 1.0, "radius_mm": 4.0}]})
    sim = TaxelSimulator(scene, mesh, (4, 4), Compliance(100.0, 2.0, 0.01), rate_hz=100.0)
    sim._make(7)  # noqa: SLF001 - the board powered on at tick 7: that frame is number 0
    sim._make(8)  # noqa: SLF001
    sim._make(12)  # noqa: SLF001 - ticks 9-11 never sent (a stall): numbers 2-4 missing
    assert [sim.scene_time(s) for s in (0, 1, 5)] == [0.07, 0.08, 0.12]
    assert sim.scene_time(2) is None and sim.truth(5) is not None
    assert np.allclose(sim.truth(0), scene.displacement_at(0.07, mesh))
