"""Actions on tracked contacts (issue 31): press or slip by a finger's own motion against its size,
speeds over frame time, never over one frame interval, and the evidence naming the finger."""

from __future__ import annotations

import numpy as np
import pytest

from wott_hub.examples import example_device
from wott_hub.sim.playback import actions, play
from wott_hub.sim.scene import Scene
from wott_hub.tactile import (
    ActionDetector,
    Contact,
    FrameProcessor,
    ProcessingParams,
    TactileFrame,
)

PAD = example_device("flat")
BARREL = example_device("barrel")
MS = 1_000_000


def finger(x, y, peak=1.0, area=30.0, cid=1):
    return Contact(np.array([0]), np.array([x, y, 0.0]), np.zeros(3), peak, peak, np.zeros(3), peak, area,
                   0.1, cid)


def run(frames):
    """frames: (t_ns, [contacts]) -> (actions, evidence) over the whole sequence."""
    det = ActionDetector()
    acts, ev = [], []
    for t, cs in frames:
        acts += det.update(t, cs)
        ev += det.details
    return acts, ev


def test_a_wide_contact_drifting_a_little_presses_a_small_one_moving_as_far_slips():
    """The slip distance grows with the contact (a quarter of its radius, 2 mm at least): 2.5 mm is
    a slip for a fingertip, not for a palm-sized contact whose centre wanders as it is pressed."""
    for area, slips in ((30.0, True), (3000.0, False)):  # radius 3 mm; 31 mm (slip distance 7.7 mm)
        # 2.5 mm in the first 0.2 s, then held still
        frames = [(k * 10 * MS, [finger(0.125 * min(k, 20), 0, area=area)]) for k in range(100)]
        acts, _ = run([*frames, (1000 * MS, [])])
        assert ("slip" in acts) is slips and "press" in acts, (area, acts)
        assert acts.index("press") > acts.index("slip") if slips else True  # held still after the slide


def test_motion_while_the_finger_lifts_is_no_slip_and_no_release_speed():
    """A camera estimate's centre drifts as the press fades (the barrel: 2-3 mm): the motion of a
    contact below half its deepest is not judged."""
    frames = [(k * 10 * MS, [finger(0, 0, peak=2.0)]) for k in range(60)]
    # fading out over 0.1 s; from half its depth on, its centre drifts 3 mm
    frames += [(600 * MS + k * 10 * MS, [finger(0.75 * max(0, k - 5), 0, peak=2.0 * (1 - k / 10))])
               for k in range(1, 10)]
    acts, ev = run([*frames, (700 * MS, [])])
    assert acts == ["touch", "press", "release"]
    assert ev[-1].speed_mm_s == pytest.approx(0.0, abs=1e-9) and ev[-1].contact_id == 1


@pytest.mark.parametrize(("device", "at", "to", "radius", "depth"), [
    (PAD, [5.0, 8.0, 0.0], [17.0, 14.0, 0.0], 3.0, 0.8),
    (BARREL, [17.9, -49.1, 80.0], [17.9, -49.1, 180.0], 12.0, 4.0),
], ids=["pad", "barrel"])
def test_release_speed_is_the_slides_own(device, at, to, radius, depth):
    steps = [{"kind": "slide", "at": at, "to": to, "start_s": 0.1, "duration_s": 1.0, "depth_mm": depth,
              "radius_mm": radius}]
    results = play(device.mesh, steps, params=ProcessingParams(epsilon_mm=device.epsilon_mm))
    scene = Scene.from_dict({"step": steps})
    a, b = scene.indenters_at(0.5, device.mesh)[0].centre, scene.indenters_at(0.6, device.mesh)[0].centre
    truth = float(np.linalg.norm(b - a) / 0.1)
    ev = {e.action: e for r in results for e in r.details}
    assert ev["release"].speed_mm_s == pytest.approx(truth, rel=0.2)
    assert ev["slip"].speed_mm_s == pytest.approx(truth, rel=0.2)
    assert actions(results) == ["touch", "slip", "release"]


def test_jittered_frame_stamps_give_bounded_speeds():
    """Frames stamped as a serial link hands them over: in bunches with the same stamp, then late.
    Speeds over one interval exploded (up to 5e8 mm/s); over frame time they stay the slide's."""
    steps = [{"kind": "slide", "at": [5.0, 8.0, 0.0], "to": [17.0, 14.0, 0.0], "start_s": 0.1,
              "duration_s": 1.0, "depth_mm": 0.8, "radius_mm": 3.0}]
    scene = Scene.from_dict({"step": steps})
    rng = np.random.default_rng(4)
    proc = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=PAD.epsilon_mm))
    stamp, events = 0, []
    for k in range(150):
        t = k / 100  # the board's 100 Hz
        if k % 3 == 0:  # every third frame a new read: up to 25 ms late, its frames stamped alike
            stamp = max(stamp, int((t + rng.uniform(0, 0.025)) * 1e9))
        events += proc.process(TactileFrame(stamp, scene.displacement_at(t, PAD.mesh))).details
    truth = float(np.hypot(12.0, 6.0))  # mm in 1 s
    speeds = {e.action: e.speed_mm_s for e in events}
    assert [e.action for e in events] == ["touch", "slip", "release"]
    assert speeds["slip"] == pytest.approx(truth, rel=0.3)
    assert speeds["release"] == pytest.approx(truth, rel=0.3)


def test_a_pinch_is_two_tracked_fingers_converging_and_no_slip():
    steps = [{"kind": "pinch", "at": [2.5, 11.25, 0.0], "to": [20.0, 11.25, 0.0], "approach_mm": 8.0,
              "start_s": 0.1, "duration_s": 0.6, "depth_mm": 0.8, "radius_mm": 3.0}]
    results = play(PAD.mesh, steps, params=ProcessingParams(epsilon_mm=PAD.epsilon_mm))
    assert actions(results) == ["touch", "pinch", "release"]
    pinch = next(e for r in results for e in r.details if e.action == "pinch")
    ids = {c.id for r in results for c in r.contacts}
    assert pinch.approach_mm > 3.0 and pinch.contacts == 2 and pinch.contact_id in ids and len(ids) == 2
    payload = pinch.payload()
    assert payload["evidence"]["contactId"] == pinch.contact_id and 0.5 <= payload["confidence"] <= 1.0


def test_every_action_names_its_finger_and_a_confidence():
    results = play(PAD.mesh, [{"kind": "press", "at": [12.0, 12.0, 0.0], "start_s": 0.1, "duration_s": 0.6,
                               "depth_mm": 0.8, "radius_mm": 3.0}], params=ProcessingParams(epsilon_mm=0.02))
    details = [e for r in results for e in r.details]
    assert [e.action for e in details] == ["touch", "press", "release"]
    cid = results[40].contacts[0].id
    assert all(e.contact_id == cid and 0.5 <= e.confidence <= 1.0 for e in details)
    press = details[1]
    assert press.moved_mm < 0.01 and press.confidence == pytest.approx(1.0)  # perfectly still: certain


def test_frames_with_the_same_stamp_are_taken_without_a_speed_from_them():
    proc = FrameProcessor(PAD.mesh, ProcessingParams(epsilon_mm=0.02))
    scene = Scene.from_dict({"step": [{"kind": "slide", "at": [5.0, 8.0, 0.0], "to": [17.0, 8.0, 0.0],
                                       "start_s": 0.0, "duration_s": 0.5, "depth_mm": 0.8,
                                       "radius_mm": 3.0}]})
    details = []
    for k in range(80):
        frame = TactileFrame((k // 4) * 40 * MS, scene.displacement_at(k / 100, PAD.mesh))  # 4 alike
        details += proc.process(frame).details
    assert all(np.isfinite(e.speed_mm_s) and e.speed_mm_s < 100 for e in details)
