"""The depth model: the parallax solve, the polynomial map, its fit and its file."""

import numpy as np
import pytest
from wott_driver_flatpad.depth import DepthModel, ParallaxSolver, fill_lost, fit_depth_model
from wott_driver_flatpad.geometry import PadLayout


def exact_area_ratio(lay: PadLayout, dz: np.ndarray, refine: int = 8) -> np.ndarray:
    """A / A_rest of markers on a surface pushed by a smooth dz field (no in-plane motion), exactly.

    The image Jacobian is taken on a grid ``refine`` times finer than the markers, from the
    optics alone: an independent check of the formula the solver inverts.
    """
    o = lay.optics
    k = refine
    fr, fc = (lay.rows - 1) * k + 1, (lay.cols - 1) * k + 1
    y, x = np.mgrid[0:fr, 0:fc] * (lay.pitch_mm / k)
    z = dz(x, y)
    px = o.project(np.column_stack([x.ravel(), y.ravel(), z.ravel()]), lay.axis_mm).reshape(fr, fc, 2)
    h = lay.pitch_mm / k
    dc, dr = np.gradient(px, h, axis=1), np.gradient(px, h, axis=0)
    det = (dc[..., 0] * dr[..., 1] - dr[..., 0] * dc[..., 1])[::k, ::k].ravel()
    return det / o.px_per_mm**2


def bump(depth, cx, cy, sigma):
    return lambda x, y: -depth * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * sigma**2))


@pytest.mark.parametrize("cx, cy", [(11.25, 11.25), (7.5, 15.0)])
def test_parallax_solve_recovers_depth_from_exact_areas(cx, cy):
    lay = PadLayout()
    f = bump(2.0, cx, cy, 2.0)  # ~0 at the clamped border, as the solver assumes
    ratio = exact_area_ratio(lay, f)
    truth = f(*lay.mesh.nodes[:, :2].T)
    truth[~lay.mesh.free] = 0.0
    model = DepthModel.physical(lay.optics)
    zeta = ParallaxSolver(lay).solve(np.log(ratio), nonlinear_passes=2)
    err = model.dz(np.expm1(zeta)) - truth
    free = lay.mesh.free
    # what is left is the grid-scale finite difference of a 2 mm bump sampled every 1.5 mm
    assert np.sqrt(np.mean(err[free] ** 2)) < 0.05
    assert np.abs(err).max() < 0.25  # of a 2 mm peak
    # without the parallax term the off-axis slope is misread as depth
    naive = model.dz(np.expm1(ParallaxSolver(lay, parallax=False).solve(np.log(ratio))))
    if (cx, cy) != (11.25, 11.25):
        assert np.sqrt(np.mean((naive - truth)[free] ** 2)) > 3 * np.sqrt(np.mean(err[free] ** 2))


def test_flat_surface_gives_zero_depth():
    lay = PadLayout(9, 12)
    zeta = ParallaxSolver(lay).solve(np.zeros(lay.n_markers))
    assert np.abs(zeta).max() < 1e-12


def test_polynomial_evaluation_and_file_round_trip(tmp_path):
    m = DepthModel((35.0, -2.0, 0.5), "test")
    x = np.array([0.0, 0.01, 0.1])
    assert np.allclose(m.dz(x), 35 * x - 2 * x**2 + 0.5 * x**3)
    m.save(tmp_path / "depth.json")
    back = DepthModel.load(tmp_path / "depth.json")
    assert back.coefficients == m.coefficients and back.source == "test"


def test_bad_model_file_is_a_clear_error(tmp_path):
    p = tmp_path / "depth.json"
    p.write_text('{"coefficients": ["NaN"]}')
    with pytest.raises(ValueError, match="finite"):
        DepthModel.load(p)


def test_fit_recovers_known_coefficients():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 0.1, 500)
    dz = 34.0 * x - 20.0 * x**2 + rng.normal(0, 1e-3, 500)
    m = fit_depth_model(x, dz, degree=2)
    assert m.coefficients[0] == pytest.approx(34.0, rel=0.01)
    assert m.coefficients[1] == pytest.approx(-20.0, rel=0.1)
    assert m.rmse_mm < 2e-3 and m.samples == 500


def test_fit_refuses_degenerate_samples():
    with pytest.raises(ValueError, match="varied samples"):
        fit_depth_model(np.zeros(50), np.zeros(50))


def test_fill_lost_takes_neighbour_means():
    lay = PadLayout(7, 7, pitch_mm=2.0, marker_radius_mm=0.4)
    values = np.arange(lay.n_markers, dtype=float)[:, None] * np.array([1.0, -1.0])
    valid = np.ones(lay.n_markers, bool)
    hole = 3 * 7 + 3
    valid[[hole, hole + 1]] = False
    out = fill_lost(lay, values, valid)
    assert np.array_equal(out[valid], values[valid])
    assert np.isfinite(out).all()
    # each hole takes the mean of its three valid neighbours in one sweep
    assert out[hole] == pytest.approx(np.mean(values[[hole - 1, hole - 7, hole + 7]], axis=0))
    assert out[hole + 1] == pytest.approx(np.mean(values[[hole + 2, hole - 6, hole + 8]], axis=0))


def test_fill_lost_reaches_a_marker_far_from_any_valid_one():
    lay = PadLayout(7, 7, pitch_mm=2.0, marker_radius_mm=0.4)
    valid = np.zeros(lay.n_markers, bool)
    valid[0] = True
    out = fill_lost(lay, np.full((lay.n_markers, 1), 5.0), valid)
    assert np.allclose(out, 5.0)
