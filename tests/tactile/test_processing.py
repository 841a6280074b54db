import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.sparse.csgraph import connected_components

from wott_hub.sim.playback import actions, play
from wott_hub.tactile import (
    FrameError,
    FrameProcessor,
    ProcessingParams,
    TactileFrame,
    flat_pad,
    taclink_barrel,
)

BARREL = taclink_barrel()
PAD = flat_pad(12, 12, pitch_mm=2.0)
LEFT, RIGHT = [0.0, 53.0, 130.0], [0.0, -53.0, 130.0]


def press(at, **kw):
    return dict(kind="press", at=at, depth_mm=3.0, radius_mm=8.0, start_s=0.2, duration_s=1.0) | kw


def test_one_press_gives_one_contact_at_the_right_place():
    results = play(BARREL, [press(LEFT)])
    held = results[int(0.7 * 120)]
    assert len(held.contacts) == 1
    c = held.contacts[0]
    assert np.linalg.norm(c.location - LEFT) < 3.0  # mesh spacing on the barrel is ~10 mm
    # the force pushes into the skin: inward (-y) at a press on the +y side
    assert c.force[1] < 0 and abs(c.force[1]) > 5 * max(abs(c.force[0]), abs(c.force[2]))
    assert actions(results) == ["touch", "press", "release"]
    info = held.contact_information()
    assert info["numOfContacts"] == 1 and len(info["contactForces"]) == 1


def test_two_separated_presses_give_two_contacts():
    results = play(BARREL, [press(LEFT), press(RIGHT)])
    held = results[int(0.7 * 120)]
    assert len(held.contacts) == 2
    locations = sorted(c.location[1] for c in held.contacts)
    assert locations[0] < -50 and locations[1] > 50


def test_slide_yields_slip():
    results = play(BARREL, [dict(kind="slide", at=[0, 53, 90], to=[0, 53, 170], depth_mm=2.0,
                                 radius_mm=8.0, start_s=0.2, duration_s=1.0)])
    acts = actions(results)
    assert acts[0] == "touch" and "slip" in acts and acts[-1] == "release"
    assert "press" not in acts  # a moving contact is not a sustained press


def test_shear_alone_yields_slip():
    # the contact stays put but the skin is dragged sideways more than it is pressed in
    results = play(PAD, [press([11.0, 11.0, 0.0], depth_mm=0.5, radius_mm=6.0, shear_mm=1.5)])
    steps = [dict(kind="slide", at=[11.0, 11.0, 0.0], to=[11.2, 11.0, 0.0], depth_mm=0.5,
                  radius_mm=6.0, start_s=0.2, duration_s=1.0, shear_mm=1.5)]
    assert "slip" not in actions(results)  # press has no shear
    assert "slip" in actions(play(PAD, steps))


def test_short_tap_yields_pat():
    results = play(BARREL, [dict(kind="tap", at=LEFT, depth_mm=2.0, radius_mm=8.0, start_s=0.2)])
    assert actions(results) == ["touch", "pat", "release"]


def test_approaching_contacts_yield_pinch():
    results = play(BARREL, [dict(kind="pinch", at=[0, 53, 80], to=[0, 53, 180], approach_mm=50,
                                 depth_mm=2.0, radius_mm=8.0, start_s=0.2, duration_s=1.0)])
    assert "pinch" in actions(results)
    assert max(len(r.contacts) for r in results) == 2


def test_fast_onset_is_a_collision():
    results = play(BARREL, [press(LEFT, depth_mm=4.0, ramp_s=0.0, duration_s=0.6)])
    assert actions(results)[0] == "collision"


def test_release_packet_after_return_to_rest():
    results = play(BARREL, [press(LEFT)], seconds=1.6)
    packets = [r.skin_deformed_detection() for r in results]
    first = next(i for i, p in enumerate(packets) if p)
    assert all(p is None for p in packets[:first])  # nothing sent while at rest
    releases = [i for i, r in enumerate(results) if r.is_release]
    assert len(releases) == 1
    rel = packets[releases[0]]
    last_deformed = packets[releases[0] - 1]
    assert {n["deformedNodeID"] for n in rel["arrayOfDeformedNodes"]} == {
        n["deformedNodeID"] for n in last_deformed["arrayOfDeformedNodes"]}
    assert all(n["deformedNodeIntensity"] == 0 for n in rel["arrayOfDeformedNodes"])
    assert all(p is None for p in packets[releases[0] + 1:])  # one release packet, then silence


def test_nothing_deformed_means_no_contact_search(monkeypatch):
    import wott_hub.tactile.processing as processing

    def boom(*a, **k):
        raise AssertionError("contact search ran on a frame at rest")

    monkeypatch.setattr(processing.ContactFinder, "find", boom)
    proc = FrameProcessor(BARREL)
    r = proc.process(TactileFrame(0, np.zeros((707, 3))))
    assert r.contacts == [] and r.skin_deformed_detection() is None


def test_clamped_nodes_are_never_reported():
    d = np.zeros((707, 3))
    d[BARREL.clamped_indices] = 5.0
    r = FrameProcessor(BARREL).process(TactileFrame(0, d))
    assert r.deformed_nodes.size == 0


def test_frames_are_checked_against_the_mesh():
    proc = FrameProcessor(BARREL)
    with pytest.raises(FrameError, match="707"):
        proc.process(TactileFrame(0, np.zeros((706, 3))))
    proc.process(TactileFrame(10, np.zeros((707, 3))))
    with pytest.raises(FrameError, match="goes back"):
        proc.process(TactileFrame(5, np.zeros((707, 3))))
    with pytest.raises(FrameError, match="NaN"):
        proc.process(TactileFrame(20, np.full((707, 3), np.nan)))


def test_epsilon_must_be_positive():
    with pytest.raises(ValueError, match="epsilon"):
        FrameProcessor(PAD, ProcessingParams(epsilon_mm=0.0))


@settings(max_examples=60, deadline=None)
@given(
    d=arrays(np.float64, (PAD.n_nodes, 3), elements=st.floats(-1.0, 1.0)),
    sparsity=arrays(np.bool_, PAD.n_nodes),
    eps=st.floats(0.01, 0.8),
    merge=st.sampled_from([(0.0, 0.0), (2.0, 0.1), (8.0, 0.5)]),
)
def test_invariants(d, sparsity, eps, merge):
    """Any field: the packet is the nodes above ε; with no birth test the contacts split every deformed
    node into connected pieces, one per peak, and two pieces that touch are apart by a real valley."""
    d = d * sparsity[:, None]
    params = ProcessingParams(epsilon_mm=eps, intensity_decimals=12, birth_noise=0.0, merge_noise=merge[0],
                              merge_ratio=merge[1])
    proc = FrameProcessor(PAD, params)
    r = proc.process(TactileFrame(0, d))
    norms = np.linalg.norm(d, axis=1)
    expected = np.flatnonzero((norms > eps) & PAD.free)
    np.testing.assert_array_equal(r.deformed_nodes, expected)  # exactly the nodes above epsilon
    if r.packet_due:
        reported = [n["deformedNodeIntensity"] for n in r.skin_deformed_detection()["arrayOfDeformedNodes"]]
        assert min(reported) > eps
    # contacts partition the deformed nodes into connected pieces
    parts = [c.nodes for c in r.contacts]
    joined = np.sort(np.concatenate(parts)) if parts else np.empty(0, int)
    np.testing.assert_array_equal(joined, expected)
    for c in r.contacts:
        n, _ = connected_components(PAD.adjacency[c.nodes][:, c.nodes], directed=False)
        assert n == 1 and c.peak == pytest.approx(norms[c.nodes].max(), rel=1e-12) and eps <= c.base < c.peak
    assert len({c.id for c in r.contacts}) == len(r.contacts) and all(c.id > 0 for c in r.contacts)
    # two contacts that touch: the valley between them is significantly below the lower peak
    merge_mm = params.merge_noise * params.below_threshold_floor * eps
    for i, a in enumerate(r.contacts):
        for b in r.contacts[i + 1:]:
            edges = PAD.adjacency[a.nodes][:, b.nodes].tocoo()
            if edges.nnz:
                saddle = np.minimum(norms[a.nodes[edges.row]], norms[b.nodes[edges.col]]).max()
                lower = min(a.peak, b.peak)
                assert lower - saddle > max(merge_mm, params.merge_ratio * lower)
    # a following frame at rest releases exactly what was deformed
    rel = proc.process(TactileFrame(1, np.zeros_like(d)))
    assert rel.is_release == bool(expected.size)
    np.testing.assert_array_equal(rel.deformed_nodes, expected)


def test_a_finite_displacement_whose_norm_overflows_is_refused_not_published_as_inf():
    """A driver scale gone wrong (taxel ``kpa_per_count = 1e300``) gives finite values whose ‖D‖ is
    inf: the frame is refused (the pipeline counts a frame error) instead of ``Infinity`` in JSON."""
    proc = FrameProcessor(PAD)
    d = np.zeros((PAD.n_nodes, 3))
    d[PAD.free_indices[:3], 2] = 1e300
    with pytest.raises(FrameError, match="overflows"):
        proc.process(TactileFrame(0, d))
    d[PAD.free_indices[:3], 2] = -0.5  # the next sane frame is processed as usual
    assert proc.process(TactileFrame(1, d)).packet_due
