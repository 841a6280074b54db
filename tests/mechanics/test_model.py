"""The assembled skin: symmetric, positive, with the stiffnesses its documentation promises."""

import numpy as np
import pytest
import scipy.sparse as sp

from wott_hub.tactile import MATERIALS, SkinMesh, flat_pad
from wott_hub.tactile.mechanics import MechanicsError, QuasiStatic, SkinModel, SkinParams
from wott_hub.tactile.mechanics.assembly import edge_set


def test_stiffness_is_symmetric_positive_definite(barrel_model):
    k = barrel_model.K
    assert abs(k - k.T).max() < 1e-12 * abs(k).max()
    lo = sp.linalg.eigsh(k, k=1, sigma=0, which="LM", return_eigenvectors=False)[0]
    assert lo > 0
    assert barrel_model.ndof == 3 * 585  # the 585 free nodes of the TacLink barrel


def test_membrane_springs_ignore_rigid_motion():
    # no foundation, no tension: a rigid translation or an infinitesimal rotation costs nothing
    pad = flat_pad(6, 7, pitch_mm=2.0, clamp_border=False)
    m = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=2.0, foundation=0.0, shear_layer=0.0))
    x = pad.nodes - pad.nodes.mean(axis=0)
    for motion in (np.tile([0.3, -0.2, 0.1], (pad.n_nodes, 1)), np.cross([0.0, 0.0, 1e-3], x),
                   np.cross([1e-3, 0.0, 0.0], x)):
        assert np.abs(m.K_full @ motion.ravel()).max() < 1e-12


def test_van_gelder_gives_the_lattice_stiffness_on_equilateral_triangles():
    # an interior edge of an equilateral lattice is a spring of sqrt(3)/2 E h
    a = 3.0
    nodes = np.array([[0, 0, 0], [a, 0, 0], [a / 2, a * np.sqrt(3) / 2, 0], [a / 2, -a * np.sqrt(3) / 2, 0]])
    mesh = SkinMesh(nodes, np.array([[0, 1, 2], [0, 3, 1]]), np.ones(4, bool))
    e = edge_set(mesh)
    shared = np.flatnonzero((e.pairs == [0, 1]).all(axis=1))[0]
    assert 0.7 * 2.0 * e.area_over_l2[shared] == pytest.approx(np.sqrt(3) / 2 * 0.7 * 2.0)
    assert e.cot_weight[shared] == pytest.approx(1 / np.sqrt(3))  # (cot 60° + cot 60°) / 2


def test_lumped_mass_is_density_times_volume():
    pad = flat_pad(9, 9, pitch_mm=2.0, clamp_border=False)
    m = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=3.0, density_kg_m3=1000.0))
    assert m.mass.sum() / 3 == pytest.approx(1000e-12 * 16.0 * 16.0 * 3.0)  # tonnes


def test_quads_have_no_preferred_diagonal(pad_model):
    # a press at the centre of a symmetric pad gives a displacement field with the pad's symmetry
    from wott_hub.tactile.mechanics import Sphere, press_on

    centre = pad_model.mesh.nodes.mean(axis=0)
    s = QuasiStatic(pad_model).solve([press_on(pad_model, centre, Sphere(4.0), depth_mm=1.0)])
    u = pad_model.to_nodes(s.u).reshape(13, 13, 3)
    assert np.allclose(u[:, :, 2], u[:, :, 2].T, atol=1e-9)  # mirror in the diagonal
    assert np.allclose(u[:, :, 2], u[::-1, :, 2], atol=1e-9)


def test_damping_is_kelvin_voigt(barrel_model):
    assert abs(barrel_model.C - barrel_model.params.damping_time_s * barrel_model.K).max() == 0


def test_material_sets_the_parameters():
    m = SkinModel.from_material(flat_pad(4, 4), MATERIALS["dragonskin-20"], 2.0, backed=True)
    assert m.params.modulus_mpa == MATERIALS["dragonskin-20"].modulus_mpa
    assert m.params.density_kg_m3 == 1080.0 and m.params.backed


@pytest.mark.parametrize("field,value", [("modulus_mpa", 0.0), ("thickness_mm", -1.0),
                                         ("damping_time_s", -1e-3), ("foundation", float("nan")),
                                         ("density_kg_m3", float("inf"))])
def test_impossible_parameters_are_refused(field, value):
    kw = dict(modulus_mpa=0.1, thickness_mm=2.0) | {field: value}
    with pytest.raises(MechanicsError, match=field):
        SkinParams(**kw)


def test_a_skin_held_by_nothing_is_refused():
    # a flat membrane with no foundation and no tension has no stiffness out of its plane
    pad = flat_pad(6, 6, pitch_mm=2.0)
    m = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=2.0, foundation=0.0, shear_layer=0.0))
    with pytest.raises(MechanicsError, match="singular"):
        QuasiStatic(m).solve([])
