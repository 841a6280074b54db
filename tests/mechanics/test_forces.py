"""Forces from displacements: exact on the model's own quasi-static answer, and through processing."""

import numpy as np
import pytest

from wott_hub.tactile import FrameProcessor, ProcessingParams, TactileFrame
from wott_hub.tactile.mechanics import (
    BackwardEuler,
    DynamicForceEstimator,
    QuasiStatic,
    Sphere,
    State,
    StiffnessForceModel,
    nodal_forces,
    press_on,
)

LEFT, RIGHT = [0.0, 53.0, 130.0], [0.0, -53.0, 130.0]


def test_stiffness_recovers_the_contact_forces_of_a_quasi_static_press(barrel_model):
    presses = [press_on(barrel_model, LEFT, Sphere(8.0), depth_mm=2.5),
               press_on(barrel_model, RIGHT, Sphere(5.0), depth_mm=1.5)]
    s = QuasiStatic(barrel_model).solve(presses)
    d = barrel_model.to_nodes(s.u)
    f = nodal_forces(barrel_model, d)
    assert np.allclose(f[barrel_model.nodes], s.f_contact.reshape(-1, 3), atol=1e-9)
    side = barrel_model.mesh.nodes[:, 1] > 0
    est = StiffnessForceModel.from_model(barrel_model)
    for k, mask in enumerate((side, ~side)):
        nodes = np.flatnonzero(mask & barrel_model.mesh.free)
        assert np.allclose(est.force(nodes, d), s.forces[k], rtol=1e-9, atol=1e-9)


def test_dynamic_estimate_adds_damping_and_inertia_exactly_for_backward_euler(barrel_model):
    # backward Euler's state satisfies M(v1 − v0)/h + C v1 + K u1 = contact force: the estimator inverts it
    integ = BackwardEuler(barrel_model)
    state, h = State.rest(barrel_model), 1 / 240
    for k in range(6):
        prev = state
        state = integ.step(state, h, [press_on(barrel_model, LEFT, Sphere(8.0), depth_mm=0.5 * (k + 1))])
    d, v = barrel_model.to_nodes(state.u), barrel_model.to_nodes(state.v)
    a = barrel_model.to_nodes((state.v - prev.v) / h)
    full = nodal_forces(barrel_model, d, v, a)[barrel_model.nodes].ravel()
    assert np.allclose(full, state.f_contact, atol=1e-8 * np.abs(state.f_contact).max())
    static = nodal_forces(barrel_model, d)[barrel_model.nodes].ravel()
    assert not np.allclose(static, state.f_contact, rtol=1e-3)  # while moving, K u alone is not enough
    est = DynamicForceEstimator(barrel_model)
    est.update(prev.t, barrel_model.to_nodes(prev.u))
    damped = est.update(state.t, d)[barrel_model.nodes].ravel()
    assert np.linalg.norm(damped - state.f_contact) < np.linalg.norm(static - state.f_contact)


def test_processing_with_the_stiffness_option_reports_the_true_force(barrel_model):
    s = QuasiStatic(barrel_model).solve([press_on(barrel_model, LEFT, Sphere(8.0), depth_mm=2.5)])
    d = barrel_model.to_nodes(s.u)
    params = ProcessingParams(modulus_mpa=barrel_model.params.modulus_mpa, thickness_mm=3.0,
                              force_model="stiffness")
    result = FrameProcessor(barrel_model.mesh, params).process(TactileFrame(0, d))
    assert len(result.contacts) == 1
    assert np.allclose(result.contacts[0].force, s.forces[0], rtol=1e-6, atol=1e-9)
    info = result.contact_information()
    assert info["contactForces"][0]["y"] == pytest.approx(round(float(s.forces[0][1]), 4))
    winkler = FrameProcessor(barrel_model.mesh, ProcessingParams(
        modulus_mpa=barrel_model.params.modulus_mpa, thickness_mm=3.0)).process(TactileFrame(0, d))
    assert not np.allclose(winkler.contacts[0].force, s.forces[0], rtol=1e-2)  # the default stays Winkler


def test_unknown_force_model_is_refused(barrel_model):
    with pytest.raises(ValueError, match="force_model"):
        FrameProcessor(barrel_model.mesh, ProcessingParams(force_model="magic"))


def test_estimate_scales_with_the_modulus(barrel_model):
    s = QuasiStatic(barrel_model).solve([press_on(barrel_model, LEFT, Sphere(8.0), depth_mm=2.0)])
    d = barrel_model.to_nodes(s.u)
    nodes = barrel_model.mesh.free_indices
    e = barrel_model.params.modulus_mpa
    soft = StiffnessForceModel(barrel_model.mesh, 0.7 * e, 3.0).force(nodes, d)
    assert np.allclose(soft, 0.7 * s.forces[0], rtol=1e-9)  # a 30 % modulus error is a 30 % force error


def test_one_product_per_frame_shared_by_the_patches(barrel_model):
    est = StiffnessForceModel.from_model(barrel_model)
    d = np.zeros((barrel_model.mesh.n_nodes, 3))
    first = est.node_forces(d)
    assert est.node_forces(d) is first and est.node_forces(d.copy()) is not first
