"""Stiff skins at a frame-long step: implicit integrators stay bounded, explicit substeps or refuses."""

import numpy as np
import pytest
import scipy.linalg as sla

from wott_hub.tactile import flat_pad
from wott_hub.tactile.mechanics import (
    BackwardEuler,
    SkinModel,
    SkinParams,
    StabilityError,
    State,
    SymplecticEuler,
    Trapezoidal,
)

FRAME = 1 / 120
PAD = flat_pad(8, 8, pitch_mm=2.0)


def _model(modulus: float, damping: float = 5e-4) -> SkinModel:
    return SkinModel(PAD, SkinParams(modulus_mpa=modulus, thickness_mm=2.0, damping_time_s=damping))


def _kicked(model: SkinModel) -> State:
    rng = np.random.default_rng(3)  # every mode excited, the stiffest included
    u = rng.normal(scale=0.1, size=model.ndof)
    v = rng.normal(scale=100.0, size=model.ndof)
    return State(0.0, u, v, np.zeros(model.ndof))


MODULI = [1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0]  # MPa: six orders of magnitude


@pytest.mark.parametrize("modulus", MODULI)
@pytest.mark.parametrize("damping", [5e-4, 0.0])
@pytest.mark.parametrize("cls", [BackwardEuler, Trapezoidal])
def test_implicit_energy_never_grows_at_one_frame_per_step(cls, modulus, damping):
    model = _model(modulus, damping)
    integ = cls(model)
    state = _kicked(model)
    energy = [model.energy(state.u, state.v)]
    for _ in range(30):
        state = integ.step(state, FRAME)
        assert np.isfinite(state.u).all() and np.isfinite(state.v).all()
        energy.append(model.energy(state.u, state.v))
    e = np.array(energy)
    assert (np.diff(e) <= 1e-9 * e[0]).all()
    if cls is BackwardEuler:
        assert e[-1] < 1e-3 * e[0]  # L-stable: a frame-long step kills the stiff modes
    elif damping == 0.0:
        assert e[-1] == pytest.approx(e[0], rel=1e-9)  # the trapezoidal rule conserves energy


@pytest.mark.parametrize("modulus", MODULI)
def test_explicit_substeps_to_stay_bounded_or_refuses_naming_the_stable_step(modulus):
    model = _model(modulus)
    integ = SymplecticEuler(model, max_substeps=5000)
    state = _kicked(model)
    e0 = model.energy(state.u, state.v)
    try:
        n = integ.substeps(FRAME)
    except StabilityError as err:
        assert f"{model.stable_step:.3g} s" in str(err) and "backward-euler" in str(err)
        assert err.stable_step_s == model.stable_step
        assert modulus >= 10.0  # the soft skins must run
        return
    for _ in range(5):
        state = integ.step(state, FRAME)
        assert np.isfinite(state.u).all()
        assert model.energy(state.u, state.v) <= 1.05 * e0
    assert n == int(np.ceil(FRAME / model.stable_step))


def test_explicit_without_substeps_refuses_a_long_step():
    model = _model(0.1)
    integ = SymplecticEuler(model, substep=False)
    with pytest.raises(StabilityError, match=r"stable step"):
        integ.step(State.rest(model), FRAME)
    integ.step(State.rest(model), model.stable_step)  # at the stable step it runs


@pytest.mark.parametrize("damping", [0.0, 5e-4])
def test_stable_step_is_safe_and_not_too_cautious(damping):
    """Against the exact bound from the eigenvalues: below it, and within a factor 2 of it."""
    model = _model(0.1, damping)
    m_half = np.diag(1 / np.sqrt(model.mass))
    w = np.sqrt(sla.eigvalsh(m_half @ model.K.toarray() @ m_half))
    zeta = damping * w / 2
    exact = float((2 / (w * (np.sqrt(1 + zeta**2) + zeta))).min())
    assert 0.5 * exact < model.stable_step <= exact
    # and the bound is a real one: 10 % over the exact step the free vibration blows up
    integ = SymplecticEuler(model, substep=False, max_step=None)
    state = _kicked(model)
    e0 = model.energy(state.u, state.v)
    over = 1.1 * exact
    model.__dict__["stable_step"] = over  # let the integrator take the unstable step
    for _ in range(300):
        state = integ.step(state, over)
    assert model.energy(state.u, state.v) > 1e3 * e0
    with pytest.raises(StabilityError, match="diverged"):  # and it says so instead of returning NaN
        for _ in range(20000):
            state = integ.step(state, over)
