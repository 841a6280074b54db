"""Frame times from the board's sequence numbers, not from when the reads happened (issue 31).

Arrivals are modelled as a serial link delivers them: the board sends every 10 ms, the
reader gets bytes late (up to 25 ms) and in bunches (a read takes every frame waiting, all
stamped alike). Stamped on arrival, a slide's speed over one interval was anything from 0
to 5e8 mm/s; stamped by the clock it is the slide's.
"""

from __future__ import annotations

import numpy as np
import pytest
from wott_driver_taxel.clock import FrameClock
from wott_driver_taxel.compliance import Compliance
from wott_driver_taxel.simulator import TaxelSimulator

from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameProcessor, ProcessingParams, TactileFrame, flat_pad

PERIOD_NS = 10_000_000
T0 = 1_700_000_000 * 10**9  # wall-clock ns, as the reader stamps


def arrivals(n: int, seed: int = 0, late_ms: float = 25.0, bunch: int = 3) -> np.ndarray:
    """When each of ``n`` frames reaches the driver: sent every 10 ms, read late, several per read."""
    rng = np.random.default_rng(seed)
    sent = T0 + np.arange(n) * PERIOD_NS
    out = np.empty(n, dtype=np.int64)
    for k in range(0, n, bunch):
        read = int(sent[min(k + bunch, n) - 1] + rng.uniform(0, late_ms) * 1e6)
        out[k:k + bunch] = read
    return np.maximum.accumulate(out)


@pytest.mark.parametrize("period_s", [0.01, None], ids=["configured", "learned"])
def test_stamps_follow_the_boards_cadence_not_the_reads(period_s):
    arr = arrivals(1500)
    clock = FrameClock(period_s)
    stamps = np.array([clock.stamp(k % 65536, int(a)) for k, a in enumerate(arr)])
    steps = np.diff(stamps) / 1e6
    assert np.diff(arr).min() == 0 and np.diff(arr).max() > 20  # what the reads alone would say
    assert steps.min() > 0  # never back, never twice the same
    settled = steps[300:]  # once the fit has a few seconds: within 10 % of the board's 10 ms (the slew)
    assert settled.min() >= 8.99 and settled.max() <= 11.01
    offset = stamps[300:] - (T0 + np.arange(300, 1500) * PERIOD_NS)
    assert np.ptp(offset) < PERIOD_NS / 2  # a steady line: its distance to the send times varies little
    assert (stamps[300:] <= arr[300:]).all()  # settled, a frame is never stamped after it arrived
    if period_s is None:
        assert clock.period_s == pytest.approx(0.01, rel=0.01)


def test_a_wrap_of_the_sequence_a_gap_and_a_restart():
    clock = FrameClock(0.01)
    sent = [(65534, 0), (65535, 1), (0, 2), (1, 3), (5, 7)]  # (seq, when sent): a wrap, 3 frames lost
    stamps = [clock.stamp(seq, T0 + k * PERIOD_NS + 2_000_000) for seq, k in sent]
    assert np.diff(stamps).tolist() == [PERIOD_NS, PERIOD_NS, PERIOD_NS, 4 * PERIOD_NS]
    # the board restarts its count: a new line, later than everything before
    after = clock.stamp(0, T0 + 20 * PERIOD_NS)
    assert after > stamps[-1] and clock.stamp(1, T0 + 21 * PERIOD_NS + 3_000_000) - after == PERIOD_NS


def test_frames_without_a_sequence_number_are_counted():
    clock = FrameClock(0.01)
    arr = arrivals(300, seed=2)
    stamps = np.array([clock.stamp(None, int(a)) for a in arr])
    assert np.diff(stamps)[100:].min() >= 8.99e6 and np.diff(stamps)[100:].max() <= 11.01e6


def test_a_taxel_slide_stamped_by_the_clock_has_the_slides_speed():
    """The whole way: the simulator's counts, the driver's displacement, stamps from late bunched
    reads through the clock, the processor; slip and release speeds within 20 % of the scene's."""
    mesh = flat_pad(16, 16, pitch_mm=4.0, clamp_border=False)
    scene = Scene.from_dict({"step": [{"kind": "slide", "at": [10.0, 20.0, 0.0], "to": [50.0, 40.0, 0.0],
                                       "start_s": 1.0, "duration_s": 1.0, "depth_mm": 1.5,
                                       "radius_mm": 10.0}]})
    compliance = Compliance(69.0, 3.0, 0.01)
    sim = TaxelSimulator(scene, mesh, (16, 16), compliance, rate_hz=100.0)
    clock = FrameClock(0.01)
    proc = FrameProcessor(mesh, ProcessingParams(epsilon_mm=0.05))
    inward = -mesh.normals
    events = []
    for k, arrived in enumerate(arrivals(230, seed=5)):
        counts, _ = sim.frame(k)
        d = compliance.normal_mm(counts.ravel())[:, None] * inward
        events += proc.process(TactileFrame(clock.stamp(k, int(arrived)), d)).details
    truth = float(np.hypot(40.0, 20.0))  # mm in 1 s
    speeds = {e.action: e.speed_mm_s for e in events}
    assert [e.action for e in events] == ["touch", "slip", "release"]
    assert speeds["slip"] == pytest.approx(truth, rel=0.2)
    assert speeds["release"] == pytest.approx(truth, rel=0.2)
