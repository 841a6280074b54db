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


def test_a_dot_two_lost_markers_contest_is_not_given_away_by_rest_position():
    """The deep pinch on the barrel (issue 31): marker a is squeezed towards b's rest position while
    both are lost; the dot that reappears between their guesses is a's, and b's search at its rest
    position must not take it (that swap outlived the release: phantom contacts at rest)."""
    ref = _grid()  # 20 px apart: gate 9 px
    a, b = 1, 2  # (20, 0) and (40, 0)
    tr = MarkerTracker(ref)
    tr.track(ref)
    frame = ref.copy()
    frame[a] += [7.0, 0.0]
    tr.track(np.delete(frame, b, axis=0))  # a seen pressed towards b, b hidden
    tr.track(np.delete(ref, [a, b], axis=0))  # both hidden
    np.testing.assert_allclose(tr.estimate[[a, b]], frame[[a, b]])  # a's guess 27, b's 40
    frame[a] = [34.0, 0.0]  # a reappears 7 px from its guess, 6 px from b's (and from b's home)
    out = tr.track(np.delete(frame, b, axis=0))
    assert np.isnan(out[[a, b]]).all()  # contested: neither, and not b by its rest position
    np.testing.assert_allclose(np.delete(out, [a, b], axis=0), np.delete(ref, [a, b], axis=0))


def test_the_grid_at_rest_is_reacquired_whatever_was_tracked():
    """Identities swapped (however: a merged blob, a guess left behind) heal as soon as the frame
    shows the grid at rest; a press elsewhere is tracked, not re-acquired."""
    ref = _grid()
    tr = MarkerTracker(ref)
    tr.track(ref)
    tr.last[[1, 2]] = tr.last[[2, 1]]  # 1 and 2 hold each other's dots, as a pinch left them
    assert tr.rest_frames == 1  # the first frame was one
    rng = np.random.default_rng(1)
    pressed = ref.copy()
    pressed[30] += [7.0, 0.0]  # beyond a quarter spacing (5 px): not the grid at rest
    out = tr.track(pressed)
    assert tr.rest_frames == 1
    np.testing.assert_allclose(out[[1, 2]], ref[[2, 1]])  # still swapped: tracking alone cannot tell
    rest = ref + rng.normal(0, 0.3, ref.shape)
    perm = rng.permutation(len(rest))
    out = tr.track(rest[perm])
    assert tr.rest_frames == 2
    np.testing.assert_allclose(out, rest)
    np.testing.assert_allclose(tr.track(ref), ref)  # and tracked on from there


def test_reacquiring_keeps_the_guess_of_a_marker_not_seen():
    ref = _grid()
    tr = MarkerTracker(ref)
    shift = np.array([4.0, 0.0])
    tr.track(ref)
    tr.track(np.delete(ref, 0, axis=0))  # marker 0 hidden (pressed out of sight)...
    light = ref.copy()
    light[0] += shift
    seen = tr.rest_frames
    out = tr.track(np.delete(light, 0, axis=0))  # ...the rest of the grid at home: re-acquired
    assert tr.rest_frames == seen + 1 and np.isnan(out[0]).all()
    np.testing.assert_allclose(out[1:], ref[1:])
    out = tr.track(light)  # it reappears 4 px off home: within its gate, found
    np.testing.assert_allclose(out, light)


def test_two_dots_at_one_home_are_not_the_grid_at_rest():
    ref = _grid()
    tr = MarkerTracker(ref)
    tr.track(ref)
    frame = np.vstack([np.delete(ref, 3, axis=0), ref[4] + [1.0, 0.0]])  # 3 gone, a second dot at 4's home
    tr.track(frame)
    assert tr.rest_frames == 1  # the first frame only


@pytest.mark.parametrize("kw", [{"home_fraction": 0.6}, {"home_fraction": 0.0}, {"rest_fraction": 0.0},
                                {"rest_fraction": 1.5}])
def test_bad_rest_settings(kw):
    with pytest.raises(ValueError):
        MarkerTracker(_grid(), **kw)
