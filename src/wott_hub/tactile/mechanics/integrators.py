"""Time integrators of the skin, behind one interface: ``step(state, h, presses, nodal_force)``.

* ``SymplecticEuler`` — explicit: v += h M⁻¹(f − Ku − Cv), then u += h v.
  First order, cheap per step (one sparse product), but only stable below
  ``model.stable_step``; it cuts a long step into substeps at that size, or
  refuses with a ``StabilityError`` that names it. Contact moves the trial
  position to the nearest admissible one in the mass norm and sets the
  velocity to match: the constraint impulse. With a lumped mass that is a
  local projection (a face probe couples only its three nodes), solved by
  the same contact solver with the diagonal matrix M/h².
* ``BackwardEuler`` — implicit, first order, L-stable: energy can only decrease
  (for a linear skin, E(n+1) − E(n) = −hvᵀCv − ½ΔvᵀMΔv − ½ΔuᵀKΔu ≤ 0), at any
  step and stiffness. One linear system per step with the matrix
  K + C/h + M/h², factorised once per step size.
* ``Trapezoidal`` — implicit Newmark (β = ¼, γ = ½), second order, A-stable and
  energy-conserving without damping; it does not damp the stiffest modes
  (its amplification tends to −1), so contact onsets ring more than with
  backward Euler.
* ``QuasiStatic`` — no inertia, no damping: K u = f with the contacts. Its
  ``step`` solves the steady state at the end of the step, so a simulator can
  use it in place of a dynamic integrator.

All states are vectors over the model's degrees of freedom; the contact
forces of each press (N, on the skin) are carried in the state as the ground
truth a force estimator is scored against.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ._threads import single_threaded
from .contact import ContactResult, ContactSolver
from .indenters import Press, PressGeometry, check_depth, press_geometry
from .model import ContactError, MechanicsError, SkinModel, StabilityError

__all__ = [
    "BackwardEuler",
    "INTEGRATORS",
    "Integrator",
    "QuasiStatic",
    "State",
    "SymplecticEuler",
    "Trapezoidal",
    "make_integrator",
]

PressSchedule = Sequence[Press] | Callable[[float], Sequence[Press]]
ForceSchedule = np.ndarray | Callable[[float], np.ndarray] | None


@dataclass(frozen=True, slots=True, eq=False)
class State:
    """The skin at time ``t``: displacement, velocity and what the indenters do to it."""

    t: float
    u: np.ndarray  # (ndof,) mm
    v: np.ndarray  # (ndof,) mm/s
    f_contact: np.ndarray  # (ndof,) contact force on each dof, N
    forces: tuple[np.ndarray, ...] = ()  # per press, total contact force on the skin (3,), N
    depths: tuple[float, ...] = ()  # per press, tip depth along its axis, mm
    active: tuple[np.ndarray, ...] = ()  # per press, contact probes (model.probes indices)
    a: np.ndarray | None = field(default=None)  # acceleration (kept by the trapezoidal rule)

    @classmethod
    def rest(cls, model: SkinModel, t: float = 0.0) -> State:
        z = np.zeros(model.ndof)
        return cls(t, z, z.copy(), z.copy())


class Integrator(ABC):
    """One way of advancing a ``State`` by a step ``h`` (seconds) under presses and nodal forces."""

    name: str = ""
    order: int = 1
    implicit: bool = True

    def __init__(self, model: SkinModel) -> None:
        self.model = model
        self._geom_cache: OrderedDict[tuple[object, bytes, bytes], PressGeometry] = OrderedDict()

    @abstractmethod
    def step(
        self, state: State, h: float, presses: PressSchedule = (), nodal_force: ForceSchedule = None
    ) -> State: ...

    # -- shared helpers --------------------------------------------------------------------
    def _check_h(self, h: float) -> float:
        h = float(h)
        if not (math.isfinite(h) and h > 0):
            raise MechanicsError(f"time step must be a positive number of seconds, got {h}")
        return h

    def _presses(self, presses: PressSchedule, t: float) -> list[Press]:
        out = list(presses(t) if callable(presses) else presses)
        for p in out:
            if not isinstance(p, Press):
                raise MechanicsError(f"expected Press objects, got {type(p).__name__}")
        return out

    def _force(self, nodal_force: ForceSchedule, t: float) -> np.ndarray:
        if nodal_force is None:
            return np.zeros(self.model.ndof)
        f = nodal_force(t) if callable(nodal_force) else nodal_force
        f = np.asarray(f, dtype=float)
        if not np.isfinite(f).all():
            raise MechanicsError("nodal force has NaN/Inf values")
        if f.shape == (self.model.mesh.n_nodes, 3):
            f = f[self.model.nodes].ravel()
        if f.shape != (self.model.ndof,):
            raise MechanicsError(f"nodal force must be a finite ({self.model.mesh.n_nodes}, 3) array in N")
        return f

    def geometries(self, presses: list[Press]) -> list[PressGeometry]:
        """Resolve presses against the model, reusing the geometry of a press that did not move."""
        out: list[PressGeometry] = []
        for p in presses:
            key = (p.shape, p.point.tobytes(), p.axis.tobytes())
            g = self._geom_cache.get(key)
            if g is None:
                g = press_geometry(self.model, p)
                self._geom_cache[key] = g
                if len(self._geom_cache) > 64:
                    self._geom_cache.popitem(last=False)
            else:
                self._geom_cache.move_to_end(key)
            out.append(g.with_press(p))
        for g in out:
            p = g.press
            if p.force_n and g.probes.size == 0:
                raise ContactError(f"a {p.force_n:g} N press at {np.round(p.point, 3).tolist()} touches no "
                                   "free node: nothing can push back")
            if p.depth_mm is not None and p.depth_mm > g.first_touch_depth:
                check_depth(self.model, p, p.depth_mm)
        return out

    def _after_contact(self, geoms: list[PressGeometry], res: ContactResult) -> None:
        for g, d in zip(geoms, res.depths, strict=True):
            if g.press.force_n:
                check_depth(self.model, g.press, d)


class _ImplicitBase(Integrator):
    """Implicit methods: a factorised ``K + c₁C + c₂M`` per step size, reused across steps."""

    c1: float = 1.0  # coefficients of C/h and M/h² in the step matrix
    c2: float = 1.0

    def __init__(self, model: SkinModel, *, cache_bytes: float = 128e6) -> None:
        super().__init__(model)
        self.cache_bytes = cache_bytes
        self._solvers: OrderedDict[float, ContactSolver] = OrderedDict()

    def solver(self, h: float) -> ContactSolver:
        key = float(np.float32(h))  # steps equal to 7 digits share a factorisation
        s = self._solvers.get(key)
        if s is None:
            m = self.model
            a = m.K + (self.c1 / h) * m.C + sp.diags((self.c2 / h**2) * m.mass)
            s = ContactSolver(a, m.probe_slots, m.probes.weights, stiffness_diag=m.K.diagonal(),
                              cache_bytes=self.cache_bytes)
            self._solvers[key] = s
            if len(self._solvers) > 3:
                self._solvers.popitem(last=False)
        else:
            self._solvers.move_to_end(key)
        return s

    def _contact_solve(self, h: float, rhs: np.ndarray, t1: float, presses: PressSchedule,
                       state: State) -> tuple[ContactResult, list[PressGeometry]]:
        geoms = self.geometries(self._presses(presses, t1))
        res = self.solver(h).solve_contact(rhs, geoms, warm=state.active or None)
        self._after_contact(geoms, res)
        return res, geoms


class BackwardEuler(_ImplicitBase):
    name = "backward-euler"
    order = 1

    def step(
        self, state: State, h: float, presses: PressSchedule = (), nodal_force: ForceSchedule = None
    ) -> State:
        h = self._check_h(h)
        m = self.model
        t1 = state.t + h
        rhs = self._force(nodal_force, t1) + m.mass * (state.u + h * state.v) / h**2 + (m.C @ state.u) / h
        res, _ = self._contact_solve(h, rhs, t1, presses, state)
        u1 = res.x
        return State(t1, u1, (u1 - state.u) / h, res.nodal, res.forces, res.depths, res.active)


class Trapezoidal(_ImplicitBase):
    name = "trapezoidal"
    order = 2
    c1, c2 = 2.0, 4.0

    def step(
        self, state: State, h: float, presses: PressSchedule = (), nodal_force: ForceSchedule = None
    ) -> State:
        h = self._check_h(h)
        m = self.model
        t1 = state.t + h
        a0 = state.a
        if a0 is None:
            f0 = self._force(nodal_force, state.t) + state.f_contact
            a0 = (f0 - m.K @ state.u - m.C @ state.v) / m.mass
        rhs = (self._force(nodal_force, t1) + m.mass * (4 * (state.u + h * state.v) / h**2 + a0)
               + m.C @ (2 * state.u / h + state.v))
        res, _ = self._contact_solve(h, rhs, t1, presses, state)
        u1 = res.x
        a1 = 4 * (u1 - state.u - h * state.v) / h**2 - a0
        v1 = 2 * (u1 - state.u) / h - state.v
        return State(t1, u1, v1, res.nodal, res.forces, res.depths, res.active, a1)


class QuasiStatic(_ImplicitBase):
    """The steady state K u = f under the presses; ``step`` jumps to the one at t + h."""

    name = "quasi-static"
    order = 0

    def solver(self, h: float = 0.0) -> ContactSolver:
        s = self._solvers.get(0.0)
        if s is None:
            m = self.model
            s = ContactSolver(m.K, m.probe_slots, m.probes.weights, cache_bytes=self.cache_bytes)
            self._solvers[0.0] = s
        return s

    def solve(self, presses: PressSchedule = (), nodal_force: ForceSchedule = None, *, t: float = 0.0,
              warm: State | None = None) -> State:
        rhs = self._force(nodal_force, t)
        geoms = self.geometries(self._presses(presses, t))
        res = self.solver().solve_contact(rhs, geoms, warm=warm.active if warm is not None else None)
        self._after_contact(geoms, res)
        z = np.zeros(self.model.ndof)
        return State(t, res.x, z, res.nodal, res.forces, res.depths, res.active)

    def step(
        self, state: State, h: float, presses: PressSchedule = (), nodal_force: ForceSchedule = None
    ) -> State:
        h = self._check_h(h)
        s = self.solve(presses, nodal_force, t=state.t + h, warm=state)
        return State(s.t, s.u, (s.u - state.u) / h, s.f_contact, s.forces, s.depths, s.active)


class SymplecticEuler(Integrator):
    """Explicit, substepping at the stable step (or refusing when ``substep`` is False)."""

    name = "symplectic-euler"
    order = 1
    implicit = False

    def __init__(self, model: SkinModel, *, substep: bool = True, max_substeps: int = 200_000,
                 max_step: float | None = None) -> None:
        super().__init__(model)
        self.substep = substep
        self.max_substeps = int(max_substeps)
        self.max_step = max_step
        self._k_diag = model.K.diagonal()

    @property
    def substep_size(self) -> float:
        hs = self.model.stable_step
        return min(hs, self.max_step) if self.max_step else hs

    def substeps(self, h: float) -> int:
        """How many substeps a step of h takes; raises StabilityError when it cannot be done."""
        h = self._check_h(h)
        hs = self.model.stable_step
        limit = self.substep_size
        n = max(1, math.ceil(h / limit * (1 - 1e-12)))
        if h > hs * (1 + 1e-12) and not self.substep:
            raise StabilityError(
                f"explicit step {h:.3g} s exceeds the stable step {hs:.3g} s of this skin "
                f"(highest frequency ≤ {self.model.omega_max:.4g} rad/s); take steps ≤ {hs:.3g} s, "
                "allow substeps, or use an implicit integrator", hs)
        if n > self.max_substeps:
            raise StabilityError(
                f"explicit step {h:.3g} s needs {n} substeps of the stable step {hs:.3g} s, more than the "
                f"limit of {self.max_substeps}: this skin is too stiff for an explicit integrator at this "
                "frame rate; use backward-euler", hs)
        return n

    @single_threaded
    def step(
        self, state: State, h: float, presses: PressSchedule = (), nodal_force: ForceSchedule = None
    ) -> State:
        n = self.substeps(h)
        dt = h / n
        m = self.model
        k_mat, mass = m.K, m.mass
        tau, alpha = m.params.damping_time_s, m.params.mass_damping_per_s  # C = τK + αM: one product
        u, v = state.u.copy(), state.v.copy()
        f_acc = np.zeros(m.ndof)
        static_presses = not callable(presses)
        geoms = self.geometries(self._presses(presses, state.t + h)) if static_presses else None
        static_force = nodal_force is None or not callable(nodal_force)
        f_ext = self._force(nodal_force, state.t) if static_force else None
        projector: ContactSolver | None = None
        res: ContactResult | None = None
        press_acc: list[np.ndarray] = []
        t = state.t
        with np.errstate(over="ignore", invalid="ignore"):  # divergence is reported below
            for _ in range(n):
                f = f_ext if static_force else self._force(nodal_force, t)
                v += dt * ((f - k_mat @ (u + tau * v)) / mass - alpha * v)
                t += dt
                if not static_presses:
                    geoms = self.geometries(self._presses(presses, t))
                if not geoms:
                    u += dt * v
                    continue
                # contact: the nearest admissible position in the mass norm (lumped mass: a local projection)
                projector = projector or ContactSolver(mass / dt**2, m.probe_slots, m.probes.weights,
                                                       stiffness_diag=self._k_diag)
                warm = res.active if res is not None else (state.active or None)
                res = projector.solve_contact(projector.d * (u + dt * v), geoms, warm=warm)
                self._after_contact(geoms, res)
                v = (res.x - u) / dt
                u = res.x
                f_acc += res.nodal
                press_acc.extend(np.zeros(3) for _ in range(len(res.forces) - len(press_acc)))
                for k, fk in enumerate(res.forces):
                    press_acc[k] = press_acc[k] + fk
        if not (np.isfinite(u).all() and np.isfinite(v).all()):
            raise StabilityError(f"explicit integration diverged at t = {t:.6g} s, substeps of {dt:.3g} s "
                                 f"(stable step {self.model.stable_step:.3g} s)", self.model.stable_step)
        if res is not None and geoms:
            forces_avg = tuple(f / n for f in press_acc[: len(geoms)])
            return State(t, u, v, f_acc / n, forces_avg, res.depths, res.active)
        return State(t, u, v, np.zeros(m.ndof))


INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (SymplecticEuler, BackwardEuler, Trapezoidal, QuasiStatic)
}


def make_integrator(name: str, model: SkinModel, **options: Any) -> Integrator:
    try:
        cls = INTEGRATORS[name]
    except KeyError:
        known = ", ".join(INTEGRATORS)
        raise MechanicsError(f"unknown integrator {name!r}: expected one of {known}") from None
    return cls(model, **options)
