"""Optics and layout: the numbers docs/flat-pad.md states, and the refusals."""

import numpy as np
import pytest
from wott_driver_flatpad.camera import PadOptics
from wott_driver_flatpad.estimator import ReferenceNotFound, order_grid
from wott_driver_flatpad.geometry import PadLayout


def test_default_camera_scale_is_about_19_px_per_mm():
    o = PadOptics()
    assert o.z_eff_mm == pytest.approx(20.0 + 3.0 / 1.49 + 4.0 / 1.41)
    assert o.px_per_mm == pytest.approx(480.0 / o.z_eff_mm)
    assert 19.0 < o.px_per_mm < 19.6


def test_project_backproject_round_trip_at_depth():
    o = PadOptics()
    axis = np.array([11.25, 11.25])
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(0, 22.5, 50), rng.uniform(0, 22.5, 50), rng.uniform(-3, 0, 50)])
    px = o.project(pts, axis)
    assert np.allclose(o.backproject(px, pts[:, 2], axis), pts[:, :2])


def test_press_magnifies_by_refracted_distance():
    o = PadOptics()
    # a marker pressed 1.41 mm into a gel of index 1.41 comes 1 mm closer optically
    assert o.scale(-1.41) == pytest.approx(o.focal_px / (o.z_eff_mm - 1.0))


def test_markers_are_mesh_nodes_in_order():
    lay = PadLayout(7, 9, pitch_mm=2.5, marker_radius_mm=0.5)
    assert lay.mesh.n_nodes == 63
    r, c = 3, 5
    i = r * lay.cols + c
    assert np.allclose(lay.mesh.nodes[i, :2], [c * 2.5, r * 2.5])
    assert lay.rest_px[i + 1, 0] > lay.rest_px[i, 0]  # next column: right in the image
    assert lay.rest_px[i + lay.cols, 1] > lay.rest_px[i, 1]  # next row: down in the image


@pytest.mark.parametrize("rows, cols", [(6, 9), (7, 17), (16, 5)])
def test_grid_size_outside_7_to_16_is_refused(rows, cols):
    with pytest.raises(ValueError, match="7..16"):
        PadLayout(rows, cols)


def test_grid_that_does_not_fit_the_image_is_refused():
    with pytest.raises(ValueError, match="camera sees"):
        PadLayout(16, 16, pitch_mm=2.0)


def test_a_grid_that_fits_the_view_but_not_the_margin_says_so():
    """Issue 44: "spans 16.5 x 13.2 mm but the camera sees 18.9 x 14.2 mm" read as a contradiction."""
    with pytest.raises(ValueError) as e:
        PadLayout(9, 11, pitch_mm=1.65, optics=PadOptics(focal_px=33.9 * PadOptics().z_eff_mm))
    text = str(e.value)
    assert "spans 16.5 x 13.2 mm" in text and "camera sees 18.9 x 14.2 mm" in text
    assert "may use 17.3 x 12.6 mm" in text and "between a marker and the image's edge" in text


def test_mm_per_px_sets_the_scale():
    from wott_driver_flatpad.settings import PadSettings, layout_from

    from wott_hub.plugin_api import read_settings

    s = read_settings(PadSettings, {"rows": 9, "cols": 11, "pitch_mm": 1.2, "mm_per_px": 0.0295})
    lay = layout_from(s)
    assert lay.optics.px_per_mm == pytest.approx(1 / 0.0295)


def test_marker_too_big_for_pitch_is_refused():
    with pytest.raises(ValueError, match="marker_radius_mm"):
        PadLayout(pitch_mm=1.5, marker_radius_mm=0.6)


def test_order_grid_restores_node_order_from_any_detection_order():
    lay = PadLayout()
    rng = np.random.default_rng(2)
    shuffled = lay.rest_px[rng.permutation(lay.n_markers)] + rng.normal(0, 0.3, (lay.n_markers, 2))
    ordered = order_grid(shuffled, lay)
    assert np.abs(ordered - lay.rest_px).max() < 1.5


def test_order_grid_rejects_missing_and_extra_markers():
    lay = PadLayout(8, 10)
    with pytest.raises(ReferenceNotFound, match="found 79 markers"):
        order_grid(lay.rest_px[1:], lay)
    speck = np.vstack([lay.rest_px[1:], [[lay.rest_px[5, 0] + 3, lay.rest_px[5, 1]]]])
    with pytest.raises(ReferenceNotFound, match="regular"):
        order_grid(speck, lay)
