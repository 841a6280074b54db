"""Deep presses, huge indenters, degenerate cells, no damping, lonely nodes, NaN: finite or a clear error."""

import numpy as np
import pytest

from wott_hub.tactile import SkinMesh, flat_pad
from wott_hub.tactile.mechanics import (
    BackwardEuler,
    ContactError,
    FlatPunch,
    MechanicsError,
    Press,
    QuasiStatic,
    SkinModel,
    SkinParams,
    Sphere,
    StabilityError,
    State,
    SymplecticEuler,
    Trapezoidal,
    press_on,
)

FRAME = 1 / 120
INTEGRATORS = [QuasiStatic, BackwardEuler, Trapezoidal, SymplecticEuler]


def _run(model: SkinModel, presses, cls=BackwardEuler, frames: int = 3) -> State:
    integ = cls(model)
    if cls is SymplecticEuler:
        frames = 1  # hundreds of substeps each: one frame shows the same
    state = State.rest(model)
    for _ in range(frames):
        state = integ.step(state, FRAME, presses)
        assert np.isfinite(state.u).all() and np.isfinite(state.v).all()
        assert all(np.isfinite(f).all() for f in state.forces)
    return state


def _centre(model):
    return model.mesh.nodes[model.mesh.free].mean(axis=0)


@pytest.mark.parametrize("cls", INTEGRATORS)
def test_press_deeper_than_the_skin(cls, barrel_model):
    # an air-backed barrel can be pressed past its thickness: the linear skin goes on, finite
    s = _run(barrel_model, [press_on(barrel_model, [0, 53, 130], Sphere(10.0), depth_mm=8.0)], cls)
    assert np.linalg.norm(s.forces[0]) > 0
    assert np.abs(s.u).max() == pytest.approx(8.0, rel=0.05)


def test_press_through_a_backed_skin_is_refused():
    pad = flat_pad(10, 10, pitch_mm=2.0)
    model = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=2.0, backed=True))
    ok = press_on(model, _centre(model), Sphere(4.0), depth_mm=1.5)
    _run(model, [ok])
    deep = press_on(model, _centre(model), Sphere(4.0), depth_mm=2.5)
    with pytest.raises(ContactError, match="deeper than the 2 mm skin"):
        _run(model, [deep])
    # by force: a force that would need more than the thickness is refused as well
    with pytest.raises(ContactError, match="needs"):
        QuasiStatic(model).solve([press_on(model, _centre(model), Sphere(4.0), force_n=50.0)])


@pytest.mark.parametrize("shape", [Sphere(1000.0), FlatPunch(1000.0)])
@pytest.mark.parametrize("cls", INTEGRATORS)
def test_indenter_larger_than_the_skin(shape, cls, pad_model):
    centre = _centre(pad_model)
    s = _run(pad_model, [press_on(pad_model, centre, shape, depth_mm=0.5)], cls)
    free = pad_model.mesh.free
    r = np.linalg.norm(pad_model.mesh.nodes[free] - centre, axis=1)
    expected = -(0.5 - shape.setback(r))  # every free node on the indenter's face
    assert np.allclose(pad_model.to_nodes(s.u)[free, 2], expected, atol=2e-3)


def test_huge_contact_on_a_big_skin_uses_the_sparse_path():
    # the dense Schur complement would not fit a tiny budget: the bordered system is factorised instead
    pad = flat_pad(30, 30, pitch_mm=1.0)
    model = SkinModel(pad, SkinParams(modulus_mpa=0.1, thickness_mm=2.0))
    qs = QuasiStatic(model, cache_bytes=1e5)
    s = qs.solve([press_on(model, _centre(model), FlatPunch(1000.0), depth_mm=0.3)])
    dense = QuasiStatic(model).solve([press_on(model, _centre(model), FlatPunch(1000.0), depth_mm=0.3)])
    assert np.allclose(s.u, dense.u, atol=1e-9) and np.allclose(s.forces, dense.forces, rtol=1e-7)


def _degenerate_mesh() -> SkinMesh:
    """A 6 x 6 pad with a duplicated node (zero-length edge), a sliver and a nearly flipped triangle."""
    pad = flat_pad(6, 6, pitch_mm=2.0)
    nodes = pad.nodes.copy()
    c = pad.cells
    tris = np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]])
    nodes[14] = nodes[15] + [1e-12, 0, 0]  # node 14 on top of node 15: zero-length edge 14-15
    nodes[21] = 0.5 * (nodes[20] + nodes[22]) + [0, 1e-9, 0]  # sliver: 20-21-22 nearly collinear
    nodes[8] = nodes[9] + [0.0, 2.0 - 1e-7, 0]  # node 8 pushed almost onto node 9 + pitch: a flipped cell
    return SkinMesh(nodes, tris, pad.free)


@pytest.mark.parametrize("cls", INTEGRATORS)
def test_degenerate_and_inverted_cells_stay_finite(cls):
    model = SkinModel(_degenerate_mesh(), SkinParams(modulus_mpa=0.1, thickness_mm=2.0))
    assert np.isfinite(model.K.data).all() and np.isfinite(model.mass).all() and (model.mass > 0).all()
    presses = [press_on(model, model.mesh.nodes[15], Sphere(3.0), depth_mm=0.5)]
    if cls is SymplecticEuler:  # the capped stiffness makes the stable step tiny: refused, clearly
        with pytest.raises(StabilityError, match=r"substeps of the stable step .* use backward-euler"):
            SymplecticEuler(model).step(State.rest(model), FRAME, presses)
        return
    else:
        s = _run(model, presses, cls)
    u = model.to_nodes(s.u)
    assert np.allclose(u[14], u[15], atol=0.05)  # coincident nodes move together


def test_zero_damping_runs_with_every_integrator(pad_model):
    from dataclasses import replace

    model = SkinModel(pad_model.mesh, replace(pad_model.params, damping_time_s=0.0))
    press = [press_on(model, _centre(model), Sphere(4.0), depth_mm=0.8)]
    for cls in INTEGRATORS:
        s = _run(model, press, cls, frames=4)
        assert s.forces[0][2] < 0


def test_node_with_no_neighbours_is_held_fixed():
    pad = flat_pad(6, 6, pitch_mm=2.0)
    nodes = np.vstack([pad.nodes, [[5.0, 5.0, 3.0]]])
    mesh = SkinMesh(nodes, pad.cells, np.append(pad.free, True))
    model = SkinModel(mesh, SkinParams(modulus_mpa=0.1, thickness_mm=2.0))
    assert model.isolated_nodes.tolist() == [36]
    s = _run(model, [press_on(model, [5.0, 5.0, 0.0], Sphere(3.0), depth_mm=0.5)])
    u = model.to_nodes(s.u)
    assert (u[36] == 0).all() and np.abs(u).max() > 0.1
    with pytest.raises(MechanicsError, match="no surface normal"):
        press_on(model, [5.0, 5.0, 3.0], Sphere(3.0), depth_mm=0.5)  # aimed at the lonely node


def test_pressing_only_on_clamped_nodes(pad_model):
    corner = pad_model.mesh.nodes[0]
    s = _run(pad_model, [press_on(pad_model, corner - [20.0, 20.0, 0.0], Sphere(2.0), depth_mm=1.0)])
    assert np.abs(s.u).max() == 0 and np.allclose(s.forces[0], 0)
    with pytest.raises(ContactError, match="touches no free node"):
        _run(pad_model, [press_on(pad_model, corner - [20.0, 20.0, 0.0], Sphere(2.0), force_n=1.0)])


@pytest.mark.parametrize("bad", [
    dict(point=[np.nan, 0, 0], axis=[0, 0, -1], depth_mm=1.0),
    dict(point=[0, 0, 0], axis=[0, 0, 0], depth_mm=1.0),
    dict(point=[0, 0, 0], axis=[0, 0, -1], depth_mm=np.inf),
    dict(point=[0, 0, 0], axis=[0, 0, -1], force_n=-1.0),
    dict(point=[0, 0, 0], axis=[0, 0, -1]),
    dict(point=[0, 0, 0], axis=[0, 0, -1], depth_mm=1.0, force_n=1.0),
    dict(point=[0, 0, 0], axis=[0, 0, -1], depth_mm=1.0, shear_mm=[np.nan, 0, 0]),
])
def test_impossible_presses_are_refused(bad):
    with pytest.raises(MechanicsError):
        Press(Sphere(2.0), **bad)


@pytest.mark.parametrize("radius", [0.0, -1.0, np.nan])
def test_impossible_indenters_are_refused(radius):
    with pytest.raises(MechanicsError, match="radius"):
        Sphere(radius)
    with pytest.raises(MechanicsError, match="radius"):
        FlatPunch(radius)


def test_bad_steps_and_forces_are_refused(pad_model):
    integ = BackwardEuler(pad_model)
    for h in (0.0, -1.0, np.nan):
        with pytest.raises(MechanicsError, match="time step"):
            integ.step(State.rest(pad_model), h)
    f = np.zeros((pad_model.mesh.n_nodes, 3))
    f[5, 0] = np.nan
    with pytest.raises(MechanicsError, match="nodal force"):
        integ.step(State.rest(pad_model), FRAME, nodal_force=f)
