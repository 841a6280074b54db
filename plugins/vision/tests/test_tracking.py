import numpy as np
import pytest
from wott_vision.tracking import MarkerTracker


def _grid():
    gx, gy = np.meshgrid(np.arange(0, 200, 20.0), np.arange(0, 100, 20.0))
    return np.column_stack([gx.ravel(), gy.ravel()])


@pytest.mark.parametrize("assignment", ["greedy", "optimal"])
def test_follows_shuffled_moving_points(assignment):
    ref = _grid()
    tr = MarkerTracker(ref, assignment=assignment)
    rng = np.random.default_rng(0)
    for k in range(30):
        # a common drift of up to 20 px plus 1 px of independent jitter: steps well inside the 9 px gate
        pos = ref + [20 * np.sin(k / 5), 10 * (1 - np.cos(k / 7))] + rng.normal(0, 1.0, ref.shape)
        perm = rng.permutation(len(pos))
        out = tr.track(pos[perm])
        np.testing.assert_allclose(out, pos)


def test_lost_markers_are_nan_and_found_again():
    ref = _grid()
    tr = MarkerTracker(ref)
    moved = ref + [3.0, 0.0]
    out = tr.track(moved[5:])  # the first five are not detected
    assert np.isnan(out[:5]).all() and np.allclose(out[5:], moved[5:])
    # a marker lost while displaced comes back home: it is searched for at its reference too
    back = ref.copy()
    back[:5] += [7.0, 0.0]  # 4 px from where it was last seen... but never seen there: last = ref
    out = tr.track(back)
    np.testing.assert_allclose(out, back)


def test_lost_mid_press_found_after_release():
    ref = _grid()
    tr = MarkerTracker(ref)
    pressed = ref.copy()
    pressed[0] += [6.0, 0.0]
    tr.track(pressed)  # seen pressed
    tr.track(pressed[1:])  # then lost
    out = tr.track(ref)  # released: 6 px from last sighting, 0 from home
    np.testing.assert_allclose(out, ref)


def test_claimed_point_goes_to_the_closer_marker_and_gate_scales_with_spacing():
    ref = np.array([[0.0, 0.0], [4.0, 0.0], [100.0, 0.0]])
    tr = MarkerTracker(ref)
    assert tr.gate[0] == pytest.approx(0.45 * 4) and tr.gate[2] == pytest.approx(25.0)
    out = tr.track(np.array([[1.0, 0.0], [115.0, 0.0]]))
    assert np.allclose(out[0], [1.0, 0.0]) and np.isnan(out[1]).all()
    assert np.allclose(out[2], [115.0, 0.0])


def test_spurious_and_empty_detections():
    ref = _grid()
    tr = MarkerTracker(ref)
    junk = np.array([[500.0, 500.0], [np.nan, 1.0]])
    out = tr.track(np.concatenate([ref, junk]))
    np.testing.assert_allclose(out, ref)
    assert np.isnan(tr.track(np.empty((0, 2)))).all()
    np.testing.assert_allclose(tr.track(ref), ref)


def test_prediction_follows_an_accelerating_slide():
    ref = _grid()
    plain, pred = MarkerTracker(ref), MarkerTracker(ref, predict=True)
    plain_ok = []
    for k in range(1, 7):
        pos = ref + [1.5 * k * (k + 1), 0.0]  # steps of 3, 6, ... 18 px: past the 9 px gate
        a, b = plain.track(pos), pred.track(pos)
        np.testing.assert_allclose(b, pos)  # constant velocity is off by 3 px only
        plain_ok.append(np.allclose(a, pos))
    assert plain_ok[0] and not all(plain_ok)


def test_bad_reference():
    for bad in (np.zeros((0, 2)), np.zeros((3, 3)), np.array([[np.nan, 0.0]])):
        with pytest.raises(ValueError):
            MarkerTracker(bad)
    with pytest.raises(ValueError):
        MarkerTracker(_grid(), assignment="magic")


def test_a_blob_twice_its_markers_area_is_two_markers_merged():
    ref = _grid()
    tr = MarkerTracker(ref)
    areas = np.full(len(ref), 30.0)
    np.testing.assert_allclose(tr.track(ref, areas), ref)  # first frame: the reference areas
    pressed = ref.copy()
    pressed[0] = pressed[1] = (ref[0] + ref[1]) / 2 + [0.5, 0.0]  # 0 and 1 pressed together...
    blob = np.delete(pressed, 1, axis=0)  # ...seen as one blob of twice the area
    blob_areas = np.delete(areas, 1)
    blob_areas[0] = 60.0
    out = tr.track(blob, blob_areas)
    assert np.isnan(out[:2]).all()  # neither marker takes the merged blob
    np.testing.assert_allclose(out[2:], ref[2:])
    assert tr.match[0] == -1 and tr.match[2] == 1


def test_lost_markers_ride_along_with_their_neighbours():
    ref = _grid()
    tr = MarkerTracker(ref)
    shift = np.array([4.0, -2.0])
    for k in range(1, 4):
        seen = ref[1:] + k * shift  # marker 0 hidden; everything moves together
        out = tr.track(seen)
        assert np.isnan(out[0]).all()
        np.testing.assert_allclose(tr.estimate[0], ref[0] + k * shift)  # carried by its neighbours
    out = tr.track(ref + 4 * shift)  # it reappears 4 steps away from home: found at the carried guess
    np.testing.assert_allclose(out, ref + 4 * shift)
