"""``wott-hub bench accuracy`` scores what it says (issue 31): on the ground-truth pad's two close presses,
connected sets get the count wrong in every steady frame and peaks right in every one.

One scene family and case only (the ground-truth pad plays in well under a second); the whole
benchmark takes minutes (docs/benchmarks.md).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_bench_tells_peaks_from_connected_sets_on_two_close_presses(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    from bench_accuracy.cases import CASES
    from bench_accuracy.families import FAMILIES, record
    from bench_accuracy.score import score
    from bench_accuracy.tables import summary
    from bench_accuracy.truth import frame_truths
    from bench_accuracy.variants import DEFAULT, Variant, run

    i, case = next((i, c) for i, c in enumerate(CASES["pad"]) if c.name == "two-close A")
    rec = record(FAMILIES["scene pad"], case, i)
    truths = frame_truths(rec)
    assert sum(t.steady for t in truths) > 90 and sum(t.rest for t in truths) > 50
    results = {}
    for variant in (DEFAULT, Variant("sets", lambda p: replace(p, segmentation="components"))):
        kept, res, times, refused = run(rec, variant)
        assert refused == 0 and len(times) == len(rec.frames)
        results[variant.name] = summary([score(rec, [truths[k] for k in kept], res, times)])
    peaks, sets = results["default"], results["sets"]
    assert peaks["right"] == peaks["steady"] and peaks["loc_median"] < 0.1 and peaks["spurious"] == 0
    assert sets["right"] == 0 and sets["spurious"] > 0  # one contact between the presses, matching neither
    assert peaks["reported"] == peaks["expected"] == 3 and peaks["static_slip"] == 0
    assert peaks["phantom"] == sets["phantom"] == 0


def test_after_a_deep_pinch_on_the_camera_barrel_the_grid_is_back_and_nothing_touches_at_rest(monkeypatch):
    """The held-out pinch on the camera-simulated barrel (issue 31): its markers squeeze into merged
    blobs for half a second. Once released, every marker is tracked at its rest position again, no
    contact is reported at rest, the release is reported, and no contact matches no finger."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import numpy as np
    from bench_accuracy.cases import CASES
    from bench_accuracy.families import FAMILIES, record
    from bench_accuracy.score import score
    from bench_accuracy.truth import frame_truths
    from bench_accuracy.variants import DEFAULT, run

    i, case = next((i, c) for i, c in enumerate(CASES["barrel"]) if c.name == "pinch B")
    rec = record(FAMILIES["camera barrel"], case, i)
    truths = frame_truths(rec)
    after = [k for k, t in enumerate(truths) if t.rest and rec.scene_t[k] > 1.0]
    assert len(after) >= 5  # rest frames after the release, all scored
    kept, res, times, refused = run(rec, DEFAULT)
    assert refused == 0
    s = score(rec, [truths[k] for k in kept], res, times)
    assert s.phantom == 0 and "release" in s.reported and s.false_actions == []
    assert s.spurious <= 0.05 * s.frames
    est = rec.driver.last_estimate  # the last frame: the skin at rest
    for tracked, home in zip(est.tracked_px, rec.driver.estimator.reference_px, strict=True):
        assert np.isfinite(tracked).all()
        assert np.abs(tracked - home).max() < 1.0  # px: every marker on its own dot
