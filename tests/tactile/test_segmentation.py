"""Contacts by peak (issue 31): two fingers whose valley stays above ε are two contacts, where the
fingers are.

Recorded scenes are played through the processor (``sim.playback.play``, the scene's ground
truth frame by frame); the watershed's rules are checked on hand-made fields.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from wott_hub.examples import example_device
from wott_hub.sim.playback import actions, play
from wott_hub.sim.scene import Scene
from wott_hub.tactile import FrameProcessor, ProcessingParams, flat_pad
from wott_hub.tactile.segmentation import MeshGraph, Watershed, count_peaks

PAD = example_device("flat")  # 16 x 16 markers at 1.5 mm, ε = 0.02 mm
TAXELS = flat_pad(16, 16, pitch_mm=4.0, clamp_border=False)


def press(at, radius, depth, **kw):
    return {"kind": "press", "at": at, "start_s": 0.2, "duration_s": 0.8, "depth_mm": depth,
            "radius_mm": radius} | kw


def held(mesh, results, steps, lo=0.35, hi=0.95):
    """The frames (120 Hz) at full depth, with each finger's centre then."""
    scene = Scene.from_dict({"step": steps})
    return [(r, [i.centre for i in scene.indenters_at(k / 120, mesh)])
            for k, r in enumerate(results) if lo <= k / 120 <= hi]


def test_two_presses_two_and_a_half_tip_radii_apart_on_the_pad_are_two_contacts_at_the_presses():
    """The issue's case: 3 mm tips 7.5 mm apart; their valley (~0.1 mm) stays far above ε, so the
    deformed nodes are one connected patch (one contact between the presses, before)."""
    steps = [press([7.5, 11.25, 0.0], 3.0, 0.8), press([15.0, 11.25, 0.0], 3.0, 0.8)]
    results = play(PAD.mesh, steps, params=ProcessingParams(epsilon_mm=PAD.epsilon_mm))
    frames = held(PAD.mesh, results, steps)
    assert len(frames) > 60
    ids = set()
    for r, centres in frames:
        nodes = r.deformed_nodes
        assert connected_components(PAD.mesh.adjacency[nodes][:, nodes], directed=False)[0] == 1
        assert len(r.contacts) == 2
        for c in r.contacts:
            assert min(np.linalg.norm(c.location - p) for p in centres) < 0.1
        ids |= {c.id for c in r.contacts}
    assert len(ids) == 2  # the same two fingers throughout
    assert actions(results) == ["touch", "press", "release"]


def test_a_taxel_pinch_stays_two_fingers_down_to_two_tip_radii():
    """On the taxel array a pinch merged into one contact between the fingers below ~23 mm."""
    steps = [{"kind": "pinch", "at": [8.0, 30.0, 0.0], "to": [52.0, 30.0, 0.0], "approach_mm": 24.0,
              "start_s": 0.2, "duration_s": 0.8, "depth_mm": 1.5, "radius_mm": 10.0}]
    scene = Scene.from_dict({"step": steps})
    results = play(TAXELS, steps, params=ProcessingParams(epsilon_mm=0.05))
    gaps = []
    for k, r in enumerate(results):
        t = k / 120
        if not 0.35 <= t <= 0.95:
            continue
        fingers = [i.centre for i in scene.indenters_at(t, TAXELS)]
        gaps.append(np.linalg.norm(fingers[0] - fingers[1]))
        assert len(r.contacts) == 2, f"t={t:.3f}: fingers {gaps[-1]:.1f} mm apart"
        for c in r.contacts:
            assert min(np.linalg.norm(c.location - p) for p in fingers) < 1.0
    assert min(gaps) < 23.0  # closer than where they merged before
    assert "pinch" in actions(results) and "slip" not in actions(results)


def line(values):
    """A 3 x n strip of the pad whose middle row carries ``values`` (the rest at rest)."""
    n = len(values)
    mesh = flat_pad(3, n + 2, pitch_mm=1.0, clamp_border=False)
    w = np.zeros(mesh.n_nodes)
    w[(n + 2) + 1 + np.arange(n)] = values
    return mesh, w


def segments(values, merge_mm=0.0, merge_ratio=0.0, floor=0.1):
    mesh, w = line(values)
    deformed = np.flatnonzero(w > floor)
    graph = MeshGraph(mesh)
    rows, flat, starts = graph.neighbours_of(deformed)
    field = np.append(w, -np.inf)
    n_peaks = count_peaks(flat, starts, field, w[deformed])
    seg = Watershed(graph, deformed, rows).split(w[deformed], floor, merge_mm, merge_ratio)
    groups = np.split(deformed[seg.order], np.cumsum(seg.counts)[:-1])
    return n_peaks, [(g - (len(values) + 3)).tolist() for g in groups], seg.base


def test_a_valley_significantly_below_the_lower_peak_keeps_two_peaks_apart():
    n_peaks, groups, base = segments([0.5, 1.0, 0.5, 0.3, 0.6, 0.9, 0.4], merge_mm=0.2)
    assert n_peaks == 2
    assert groups == [[0, 1, 2], [3, 4, 5, 6]]  # the valley node climbs to its higher neighbour's peak
    assert base == [0.1, 0.3]  # the lower peak rises from the valley, the higher one from ε


@pytest.mark.parametrize("merge", [(0.7, 0.0), (0.0, 0.7)], ids=["noise", "ratio"])
def test_a_shallow_valley_merges_into_the_elder_peak(merge):
    """0.9 - 0.3 = 0.6 below the lower peak: not more than 0.7 mm, nor than 70 % of it: one contact."""
    _, groups, base = segments([0.5, 1.0, 0.5, 0.3, 0.6, 0.9, 0.4], *merge)
    assert groups == [[0, 1, 2, 3, 4, 5, 6]] and base == [0.1]


def test_a_plateau_is_one_peak_and_ties_are_counted_for_the_watershed_to_settle():
    n_peaks, groups, _ = segments([0.3, 0.8, 0.8, 0.8, 0.3])
    assert n_peaks == 3  # every node of the flat top is as high as its neighbours...
    assert groups == [[0, 1, 2, 3, 4]]  # ...but it is one top


def test_three_peaks_merge_from_the_highest_saddle_down():
    # A (1.0) - B (0.7) - C (0.9), valleys 0.6 (A-B) and 0.2 (B-C), 0.15 mm of margin: at 0.6 B is only
    # 0.1 below its peak and joins A; at 0.2 C (0.7 below its peak) stays apart from A and B
    _, groups, base = segments([1.0, 0.6, 0.7, 0.2, 0.9], merge_mm=0.15)
    assert groups == [[0, 1, 2], [3, 4]] and base == [0.1, 0.2]


def test_a_single_peak_a_patch_skips_the_watershed(monkeypatch):
    import wott_hub.tactile.segmentation as segmentation

    def boom(*a, **k):
        raise AssertionError("watershed ran on a smooth press")

    monkeypatch.setattr(segmentation.Watershed, "split", boom)
    # each centred on a marker: one top each (a press between markers has two to four equal tops, which
    # the watershed settles)
    results = play(PAD.mesh, [press([12.0, 12.0, 0.0], 3.0, 0.8), press([4.5, 4.5, 0.0], 2.0, 0.5)],
                   params=ProcessingParams(epsilon_mm=PAD.epsilon_mm))
    assert max(len(r.contacts) for r in results) == 2


def test_segmentation_components_is_the_connected_sets_of_before():
    steps = [press([7.5, 11.25, 0.0], 3.0, 0.8), press([15.0, 11.25, 0.0], 3.0, 0.8)]
    params = ProcessingParams(epsilon_mm=PAD.epsilon_mm, segmentation="components")
    r = play(PAD.mesh, steps, params=params)[60]
    assert len(r.contacts) == 1 and abs(r.contacts[0].location[0] - 11.25) < 0.1  # between the two
    with pytest.raises(ValueError, match="segmentation"):
        FrameProcessor(PAD.mesh, ProcessingParams(segmentation="blobs"))
