"""Frames that come late or not at all change nothing that is derived from them (issue 48, item 9).

A busy computer reads a camera late and drops frames; a stalled reader loses a run of them. Each
gesture of the accuracy bench's pad set is played at 30 frames/s, then with a third of its frames
dropped at random and with runs of six frames (200 ms) missing: the actions are the same, and the
contacts of every frame seen both ways are in the same places. A tap that falls wholly inside a
stall was never seen: it makes no action at all (a skipped frame is not guessed at).
(docs/processing.md, "Frames that come late or not at all".)
"""

from __future__ import annotations

import numpy as np
import pytest

from wott_hub.examples import example_device
from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameProcessor, FrameResult, ProcessingParams, TactileFrame

PAD = example_device("flat")
FPS = 30.0
PRESS = {"kind": "press", "at": [11.25, 11.25, 0.0], "start_s": 0.3, "duration_s": 1.0, "depth_mm": 0.8,
         "radius_mm": 3.0, "ramp_s": 0.1}
GESTURES = {
    "press": ([PRESS], ["touch", "press", "release"]),
    "slow press": ([PRESS | {"ramp_s": 0.35, "duration_s": 1.2}], ["touch", "press", "release"]),
    "slide": ([{"kind": "slide", "at": [5.0, 8.0, 0.0], "to": [17.0, 14.0, 0.0], "start_s": 0.3,
                "duration_s": 1.0, "depth_mm": 0.8, "radius_mm": 3.0, "ramp_s": 0.1}],
              ["touch", "slip", "release"]),
    "pinch": ([{"kind": "pinch", "at": [2.5, 11.25, 0.0], "to": [20.0, 11.25, 0.0], "approach_mm": 8.0,
                "start_s": 0.3, "duration_s": 1.0, "depth_mm": 0.8, "radius_mm": 3.0, "ramp_s": 0.1}],
              ["touch", "pinch", "release"]),
    "tap": ([{"kind": "tap", "at": [11.25, 11.25, 0.0], "start_s": 0.3, "depth_mm": 0.8, "radius_mm": 3.0}],
            ["touch", "pat", "release"]),
}


def _random_drops(n: int, seed: int) -> list[int]:
    """A third of the frames gone at random (the first kept: the skin at rest)."""
    keep = np.random.default_rng(seed).random(n) >= 1 / 3
    keep[0] = True
    return [k for k in range(n) if keep[k]]


def _stalls(n: int, offset: int) -> list[int]:
    """Six frames in every fifteen gone: a reader that stalls 200 ms every half second."""
    return [k for k in range(n) if k == 0 or (k + offset) % 15 >= 6]


def _play(steps: list[dict], frames: list[int]) -> dict[int, FrameResult]:
    """Frame k of the scene at 30 frames/s, stamped with its own time, for each k in ``frames``."""
    scene = Scene.from_dict({"step": steps})
    proc = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=PAD.epsilon_mm))
    out = {}
    for k in frames:
        t = k / FPS
        out[k] = proc.process(TactileFrame(int(round(t * 1e9)), scene.displacement_at(t, PAD.mesh)))
    return out


def _actions(results: dict[int, FrameResult]) -> list[str]:
    return [a for _, r in sorted(results.items()) for a in r.actions]


@pytest.mark.parametrize("gesture", list(GESTURES))
def test_the_same_gesture_seen_with_frames_missing_gives_the_same_actions_and_places(gesture):
    steps, expected = GESTURES[gesture]
    n = int(Scene.from_dict({"step": steps}).duration_s * FPS) + 4  # and rest frames after it
    every = _play(steps, list(range(n)))
    assert _actions(every) == expected
    for name, kept in [*((f"random drops {s}", _random_drops(n, s)) for s in range(4)),
                       *((f"stalls {o}", _stalls(n, o)) for o in (0, 5, 10))]:
        seen = _play(steps, kept)
        scene = Scene.from_dict({"step": steps})
        if not any(scene.touching(k / FPS) for k in kept):  # a tap inside a stall: nothing was seen
            assert _actions(seen) == [], name
            continue
        assert _actions(seen) == expected, (name, _actions(seen))
        for k, r in seen.items():  # each frame's contacts are where they were with every frame seen
            here = sorted(tuple(np.round(c.location, 6)) for c in r.contacts)
            there = sorted(tuple(np.round(c.location, 6)) for c in every[k].contacts)
            assert len(here) == len(there), (name, k)
            assert np.allclose(here, there, atol=1e-3) if here else True, (name, k, here, there)


def test_a_slide_read_late_in_bursts_is_the_slide_read_on_time():
    """A serial board's frames read by a busy hub: every quarter second the reader stalls 150 ms and
    then gets fifteen frames at once. Stamped by the board's cadence (the taxel driver's
    ``FrameClock``), not by their arrival, they give the actions the same frames give read on time,
    and speeds within a tenth of theirs (the clock's period is a line fitted to the arrivals: the
    bursts tilt it a little)."""
    from wott_driver_taxel.clock import FrameClock

    steps, expected = GESTURES["slide"]
    scene = Scene.from_dict({"step": steps})
    rate = 100.0
    n = int(scene.duration_s * rate) + 10

    def events(arrival_s) -> list:
        clock = FrameClock(1 / rate)
        proc = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=PAD.epsilon_mm))
        out = []
        for k in range(n):
            t_ns = clock.stamp(k, int(round((10.0 + arrival_s(k)) * 1e9)))
            out += proc.process(TactileFrame(t_ns, scene.displacement_at(k / rate, PAD.mesh))).details
        return out

    def stalled(k: int) -> float:  # frames due in a stall arrive together at its end
        due = k / rate + 0.0005
        phase = due % 0.25
        return due - phase + 0.15 if 0.05 <= phase < 0.15 else due

    on_time, late = events(lambda k: k / rate + 0.0005), events(stalled)
    assert [e.action for e in on_time] == [e.action for e in late] == expected
    for a, b in zip(on_time, late, strict=True):
        assert b.speed_mm_s == pytest.approx(a.speed_mm_s, rel=0.1, abs=0.5), (a, b)


def test_a_slides_speed_does_not_depend_on_the_frames_that_were_seen():
    """A speed is a line through a window of frame time: the slide's, with every frame or a third missing."""
    steps, _ = GESTURES["slide"]
    n = int(Scene.from_dict({"step": steps}).duration_s * FPS) + 4
    truth = float(np.hypot(12.0, 6.0))  # mm in 1 s
    for kept in (list(range(n)), _random_drops(n, 1), _stalls(n, 3)):
        ev = {e.action: e for _, r in sorted(_play(steps, kept).items()) for e in r.details}
        assert ev["slip"].speed_mm_s == pytest.approx(truth, rel=0.25)
        assert ev["release"].speed_mm_s == pytest.approx(truth, rel=0.25)
