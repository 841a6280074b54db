import numpy as np
import pytest
from wott_driver_barrel.geometry import FisheyeCamera


def test_markers_sit_on_the_free_skin_in_16_rings_of_16(layout):
    mk = layout.markers
    assert mk.n_markers == 256 and mk.rest.shape == (256, 3)
    z = mk.rest[:, 2].reshape(16, 16)
    np.testing.assert_allclose(z, np.linspace(25, 235, 16)[:, None].repeat(16, axis=1), atol=1e-9)
    az = np.degrees(np.arctan2(mk.rest[:, 1], mk.rest[:, 0])).reshape(16, 16) % 360
    np.testing.assert_allclose(az[0], np.arange(16) * 22.5, atol=1e-6)
    r = np.hypot(mk.rest[:, 0], mk.rest[:, 1])
    assert 41 < r.min() and r.max() < 53.4  # on the barrel between its rims and its belly
    np.testing.assert_allclose(mk.weights.sum(axis=1), 1.0)
    # a marker moves with its triangle: a rigid shift of the skin shifts every marker the same
    d = np.tile([0.3, -0.2, 0.1], (layout.mesh.n_nodes, 1))
    np.testing.assert_allclose(mk.marker_displacement(d), d[:256])


def test_both_cameras_see_every_marker_like_the_real_sensor(layout):
    bottom, top = layout.reference_px
    for cam, px in zip(layout.cameras, (bottom, top), strict=True):
        assert cam.visible(px).all()
        r = np.hypot(px[:, 0] - cam.cx, px[:, 1] - cam.cy).reshape(16, 16)
        assert np.ptp(r, axis=1).max() < 1.0  # a ring is a circle around the centre (mesh facets: < 1 px)
    r_bottom = np.hypot(*(bottom - [319.5, 239.5]).T).reshape(16, 16)[:, 0]
    assert 210 < r_bottom[0] < 230 and 35 < r_bottom[-1] < 45  # near ring big, far ring near the centre
    assert np.all(np.diff(r_bottom) < 0)
    r_top = np.hypot(*(top - [319.5, 239.5]).T).reshape(16, 16)[:, 0]
    np.testing.assert_allclose(r_top, r_bottom[::-1], atol=0.6)  # the barrel is symmetric


def test_equidistant_projection():
    cam = FisheyeCamera("c", 0.0, True, f_px=200.0)
    px = cam.project(np.array([[0.0, 0.0, 10.0], [10.0, 0.0, 10.0], [0.0, 5.0, 0.0]]))
    np.testing.assert_allclose(px[0], [319.5, 239.5])
    np.testing.assert_allclose(px[1], [319.5 + 200 * np.pi / 4, 239.5])
    np.testing.assert_allclose(px[2], [319.5, 239.5 + 200 * np.pi / 2])
    down = FisheyeCamera("d", 10.0, False, f_px=200.0)
    assert down.project(np.array([0.0, 5.0, 0.0]))[1] < 239.5  # mirrored: looking down the axis
    with pytest.raises(ValueError):
        FisheyeCamera("bad", 0.0, True, f_px=0.0)


def test_stereo_maps_carry_motion_from_one_camera_to_the_other(layout):
    maps = layout.stereo_maps()
    n = layout.markers.normals
    jac = layout.jacobians()
    u = -1.0 * n  # a small press along the normal
    seen_b = np.einsum("mij,mj->mi", jac[1], u)
    pred_a = np.einsum("mij,mj->mi", maps[0], seen_b)
    true_a = np.einsum("mij,mj->mi", jac[0], u)
    assert np.sqrt(np.mean((pred_a - true_a) ** 2)) < 0.05 * np.sqrt(np.mean(true_a**2))
