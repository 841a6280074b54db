"""Halving the step divides the error by 2^order, against the exact solution (matrix exponential)."""

import numpy as np
import pytest
import scipy.linalg as sla

from wott_hub.tactile import flat_pad
from wott_hub.tactile.mechanics import (
    BackwardEuler,
    SkinModel,
    SkinParams,
    State,
    SymplecticEuler,
    Trapezoidal,
)

PAD = flat_pad(7, 7, pitch_mm=2.0)
MODEL = SkinModel(PAD, SkinParams(modulus_mpa=0.1, thickness_mm=3.0, damping_time_s=1e-4))
T_END = 4e-3  # a few periods of the lowest modes


def _start() -> State:
    """A smooth bump (mostly the lowest modes), released from rest, plus a smooth step force."""
    x = MODEL.rest
    centre = x.mean(axis=0)
    bump = np.exp(-np.sum((x - centre) ** 2, axis=1) / 8.0)
    u = np.zeros((len(x), 3))
    u[:, 2] = -0.3 * bump
    return State(0.0, u.ravel(), np.zeros(MODEL.ndof), np.zeros(MODEL.ndof))


FORCE = np.zeros((PAD.n_nodes, 3))
FORCE[PAD.n_nodes // 2, 0] = 0.05  # N, a constant sideways pull on the centre node


def _exact() -> np.ndarray:
    n = MODEL.ndof
    minv = 1 / MODEL.mass
    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.eye(n)
    a[n:, :n] = -minv[:, None] * MODEL.K.toarray()
    a[n:, n:] = -minv[:, None] * MODEL.C.toarray()
    f = np.concatenate([np.zeros(n), minv * FORCE[MODEL.nodes].ravel()])
    s = _start()
    y0 = np.concatenate([s.u, s.v])
    # y' = A y + f with constant f: y(T) = e^{AT} y0 + A⁻¹(e^{AT} − I) f
    e = sla.expm(a * T_END)
    return e @ y0 + np.linalg.solve(a, (e - np.eye(2 * n)) @ f)


EXACT = _exact()


def _error(cls, steps: int) -> float:
    integ = cls(MODEL, substep=False) if cls is SymplecticEuler else cls(MODEL)
    s = _start()
    h = T_END / steps
    for _ in range(steps):
        s = integ.step(s, h, nodal_force=FORCE)
    n = MODEL.ndof
    return float(np.linalg.norm(s.u - EXACT[:n]) / np.linalg.norm(EXACT[:n]))


@pytest.mark.parametrize("cls,order,steps", [
    (BackwardEuler, 1, (200, 400, 800)),
    (Trapezoidal, 2, (50, 100, 200)),
    (SymplecticEuler, 1, (400, 800, 1600)),
])
def test_error_falls_at_the_integrators_order(cls, order, steps):
    assert T_END / steps[0] <= MODEL.stable_step or cls is not SymplecticEuler
    errors = [_error(cls, n) for n in steps]
    rates = [np.log2(a / b) for a, b in zip(errors, errors[1:], strict=False)]
    assert errors[-1] < 0.05
    assert rates[-1] == pytest.approx(order, abs=0.2), (errors, rates)
