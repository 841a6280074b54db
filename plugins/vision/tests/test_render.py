import numpy as np
import pytest
from wott_vision.render import render_markers


def test_disc_area_and_centroid_are_exact_without_blur():
    img = render_markers([[50.3, 40.7]], 6.0, size=(100, 120), blur_sigma=0.0).astype(float) / 255
    assert img.sum() == pytest.approx(np.pi * 36, rel=0.01)
    ys, xs = np.mgrid[:100, :120]
    assert (img * xs).sum() / img.sum() == pytest.approx(50.3, abs=0.01)
    assert (img * ys).sum() / img.sum() == pytest.approx(40.7, abs=0.01)


def test_per_marker_radius_nan_and_out_of_frame_markers():
    pts = np.array([[20.0, 20.0], [60.0, 20.0], [np.nan, 5.0], [-50.0, 10.0], [119.0, 99.0]])
    img = render_markers(pts, np.array([2.0, 5.0, 3.0, 3.0, 4.0]), size=(100, 120), blur_sigma=0.0)
    assert img.dtype == np.uint8 and img.shape == (100, 120)
    small = img[10:31, 10:31].astype(float).sum() / 255
    big = img[10:31, 50:71].astype(float).sum() / 255
    assert small == pytest.approx(np.pi * 4, rel=0.05)
    assert big == pytest.approx(np.pi * 25, rel=0.02)
    assert img[99, 119] == 255  # a marker on the corner is clipped, not dropped


def test_noise_is_reproducible_with_a_generator():
    a = render_markers([[30.0, 30.0]], 4.0, size=(64, 64), noise_std=5.0, rng=np.random.default_rng(3))
    b = render_markers([[30.0, 30.0]], 4.0, size=(64, 64), noise_std=5.0, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert a[0:10, 0:10].std() > 1.0


def test_bad_size():
    with pytest.raises(ValueError):
        render_markers([[1.0, 1.0]], 1.0, size=(0, 10))


def test_exposure_rounds_and_saturates_like_numpy():
    from wott_vision.render import _noise_bank, expose

    picture = np.linspace(-20.0, 280.0, 64 * 80, dtype=np.float32).reshape(64, 80)
    picture[0, :4] = [0.5, 1.5, 2.5, 254.5]  # halves round to even
    np.testing.assert_array_equal(expose(picture), np.clip(np.rint(picture), 0, 255).astype(np.uint8))
    # with noise: the window of the bank at the offset the generator draws, added and rounded once
    offset = int(np.random.default_rng(7).integers(picture.size + 1))
    window = _noise_bank(picture.size)[offset:offset + picture.size].reshape(picture.shape)
    expected = np.clip(np.rint(picture + np.float32(3.0) * window), 0, 255).astype(np.uint8)
    np.testing.assert_array_equal(expose(picture, 3.0, np.random.default_rng(7)), expected)
    # any float picture, any layout
    strided = picture.astype(np.float64)[:, ::2]
    np.testing.assert_array_equal(expose(strided, 3.0, np.random.default_rng(7)),
                                  expose(np.ascontiguousarray(strided), 3.0, np.random.default_rng(7)))


def test_sensor_noise_is_gaussian_in_a_frame_and_new_in_the_next():
    from wott_vision.render import expose

    grey = np.full((240, 320), 100.0, dtype=np.float32)
    rng = np.random.default_rng(1)
    frames = [expose(grey, 4.0, rng).astype(float) - 100.0 for _ in range(20)]
    for noise in frames:
        assert abs(noise.mean()) < 0.1 and noise.std() == pytest.approx(4.0, rel=0.03)
        # neighbouring pixels are independent
        assert abs(np.corrcoef(noise[:, :-1].ravel(), noise[:, 1:].ravel())[0, 1]) < 0.02
    # each frame's noise is new: no pixel's noise follows it to the next frame
    for a, b in zip(frames, frames[1:], strict=False):
        assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < 0.02
