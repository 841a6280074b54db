"""Solve A x = r with indenters pushing on the skin, reusing one factorisation of A.

Every implicit step, the quasi-static solve and the explicit contact
projection reduce to the same problem: minimise ½xᵀAx − rᵀx with A symmetric
positive definite, subject to the contact rows of each press — for each probe
p in contact, a·u(p) ≥ d − φ_p, plus two tangential equalities for a sticking
press — where u(p) = Σ_j w_pj x_j interpolates the probe's nodes. An
active-set loop picks the probes in contact: solve as if the active rows were
equalities, then keep exactly the probes that still penetrate (an indenter
never pulls), repeat. Warm-started from the previous step's set it usually
needs one to three iterations.

Each equality solve uses the Schur complement on the contact rows,
x = A⁻¹r + A⁻¹Bᵀλ, (BA⁻¹Bᵀ + εD)λ = g − BA⁻¹r, so A is never refactorised:
the three columns of A⁻¹ under each contact node are computed once and kept
(an LRU cache bounded in bytes). The small εD makes the projection a penalty:
each probe is held by a spring 1000 times stiffer than the skin's own
diagonal stiffness there (ε = 10⁻³), which changes the answer by about 0.1 %
and keeps the system regular when several probes on one face push on the
same three nodes. With it the loop is a semismooth Newton method on a convex,
piecewise-quadratic energy, globalised by backtracking on that energy. A
force-controlled press adds its depth as one more unknown and Σλ = F as one
more equation. When the columns would not fit the memory budget (a contact
covering most of a big skin), each iteration factorises the bordered KKT
matrix instead. For a diagonal A (the explicit integrator's projection,
A = M/h²) nothing needs caching.

The multipliers λ are the contact forces on the probes in newtons.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ._threads import single_threaded
from .indenters import PressGeometry
from .model import factorize

__all__ = ["ContactResult", "ContactSolver"]

MAX_ITERATIONS = 60
GAP_TOL_MM = 1e-9
REGULARISATION = 1e-3


@dataclass(frozen=True, slots=True, eq=False)
class ContactResult:
    x: np.ndarray  # solution (ndof,)
    nodal: np.ndarray  # (ndof,) contact force on every dof, N
    forces: tuple[np.ndarray, ...]  # per press, total force on the skin (3,), N
    depths: tuple[float, ...]  # per press, tip depth along its axis, mm
    active: tuple[np.ndarray, ...]  # per press, probe indices in contact, ascending
    iterations: int
    converged: bool


class ContactSolver:
    """A factorised SPD matrix (or a diagonal one), its cached inverse columns and the active-set loop.

    ``probe_slots``/``probe_weights`` (P, 3) say which model nodes each probe
    interpolates (slot −1: a node that does not move).
    """

    def __init__(self, a: np.ndarray | sp.spmatrix, probe_slots: np.ndarray, probe_weights: np.ndarray, *,
                 stiffness_diag: np.ndarray | None = None, cache_bytes: float = 128e6) -> None:
        self.diagonal = not sp.issparse(a)
        self.d: np.ndarray
        if self.diagonal:
            self.d = np.asarray(a, dtype=float)
            self.n = len(self.d)
            self.a = sp.diags(self.d, format="csc")
        else:
            self.a = sp.csc_matrix(a)
            self.n = self.a.shape[0]
            self.lu = factorize(self.a)
            self.d = self.a.diagonal()
        # the penalty is set against the skin's own stiffness, not A, so every integrator and step
        # size solves the same contact model
        self.k_diag = np.asarray(stiffness_diag if stiffness_diag is not None else self.d, dtype=float)
        self.probe_slots = probe_slots
        self.probe_weights = np.where(probe_slots >= 0, probe_weights, 0.0)
        self.cache_bytes = cache_bytes
        self._cols: OrderedDict[int, np.ndarray] = OrderedDict()  # node slot -> (n, 3) of A⁻¹

    def solve(self, r: np.ndarray) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        x: np.ndarray = r / self.d if self.diagonal else self.lu.solve(r)
        return x

    # -- cached columns ----------------------------------------------------------------
    @single_threaded
    def node_columns(self, slots: np.ndarray) -> np.ndarray:
        """(n, 3 len(slots)): the three columns of A⁻¹ of each node, side by side."""
        missing = [s for s in dict.fromkeys(slots.tolist()) if s not in self._cols]
        for start in range(0, len(missing), 64):
            chunk = missing[start : start + 64]
            rhs = np.zeros((self.n, 3 * len(chunk)))
            for j, s in enumerate(chunk):
                rhs[3 * s : 3 * s + 3, 3 * j : 3 * j + 3] = np.eye(3)
            sol = self.lu.solve(rhs)
            for j, s in enumerate(chunk):
                self._cols[s] = np.ascontiguousarray(sol[:, 3 * j : 3 * j + 3])
        out = np.empty((self.n, 3 * len(slots)))
        for i, s in enumerate(slots.tolist()):
            self._cols.move_to_end(s)
            out[:, 3 * i : 3 * i + 3] = self._cols[s]
        keep = max(16, int(self.cache_bytes // (2 * self.n * 3 * 8)), len(slots))
        while len(self._cols) > keep:
            self._cols.popitem(last=False)
        return out

    # -- the contact problem -------------------------------------------------------------
    @single_threaded
    def solve_contact(
        self,
        r: np.ndarray,
        geoms: list[PressGeometry],
        warm: tuple[np.ndarray, ...] | None = None,
    ) -> ContactResult:
        """Solve A x = r + Bᵀλ with the contact conditions of every press.

        ``warm`` is a previous result's ``active`` (probe indices per press). A
        press driven with zero force is not touching and takes no part.
        """
        x0 = self.solve(r)
        live = [k for k, g in enumerate(geoms) if g.press.force_n != 0.0]
        if not live:
            return self._assemble(x0, np.zeros(self.n), geoms, {}, _Rows.empty(), np.zeros(0), {}, 0, True)
        lg = [geoms[k] for k in live]
        k_pen = [1.0 / (REGULARISATION * self._flexibility(g)) for g in lg]
        sticky = any(g.press.sticks for g in lg)
        # the current point of the Newton iteration: x, its contact forces q = Ax − r, and the depths
        x, q = x0, np.zeros(self.n)
        depths = [g.press.depth_mm if g.press.depth_mm is not None else g.first_touch_depth for g in lg]
        active: list[np.ndarray] = []
        for k, g in zip(live, lg, strict=True):
            start = np.empty(0, dtype=np.int64)
            if warm is not None and k < len(warm) and len(warm[k]):
                start = np.flatnonzero(np.isin(g.probes, warm[k]))
            if start.size == 0 and g.press.depth_mm is not None:
                start = np.flatnonzero(self._gaps(x0, g, g.press.depth_mm) < 0)
            active.append(start)
        _claim_unique(lg, active, len(self.probe_slots))
        seen: set[tuple[tuple[int, ...], ...]] = set()
        monotone = False
        j_now = self._objective(x, q, r, lg, depths, k_pen)
        for it in range(1, MAX_ITERATIONS + 1):
            for k, g in enumerate(lg):  # a pushed press must touch something
                if g.press.force_n and active[k].size == 0 and g.probes.size:
                    active[k] = np.array([int(np.argmin(g.phi))])
            xn, lam, dn, rows = self._equality_solve(r, x0, lg, active)
            qn = rows.nodal(self.n, lam)
            step = 1.0
            if not sticky:  # backtrack until the penalised energy decreases (globalises Newton)
                while step > 1e-3:
                    xt, qt = x + step * (xn - x), q + step * (qn - q)
                    dt = [d + step * (e - d) for d, e in zip(depths, dn, strict=True)]
                    j_try = self._objective(xt, qt, r, lg, dt, k_pen)
                    if j_try <= j_now + 1e-12 * abs(j_now):
                        break
                    step *= 0.5
            x, q = x + step * (xn - x), q + step * (qn - q)
            depths = [d + step * (e - d) for d, e in zip(depths, dn, strict=True)]
            j_now = self._objective(x, q, r, lg, depths, k_pen)
            new_active: list[np.ndarray] = []
            claimed = np.zeros(len(self.probe_slots), dtype=bool)
            for k, g in enumerate(lg):
                pen = np.flatnonzero(self._gaps(x, g, depths[k]) < 0)
                nxt = np.union1d(active[k], pen) if monotone else pen
                nxt = nxt[~claimed[g.probes[nxt]]]
                claimed[g.probes[nxt]] = True
                new_active.append(nxt.astype(np.int64))
            same = all(np.array_equal(a, b) for a, b in zip(new_active, active, strict=True))
            done = same and step == 1.0
            if done or it == MAX_ITERATIONS:
                break
            key = tuple(tuple(a.tolist()) for a in new_active)
            if same or key in seen:
                if key in seen and not same:
                    monotone = True  # cycling: from now on only add probes, which must terminate
            seen.add(key)
            active = new_active
        per_press = {k: (dn[i], lg[i].probes[active[i]]) for i, k in enumerate(live)}
        live_index = {k: i for i, k in enumerate(live)}
        return self._assemble(xn, qn, geoms, live_index, rows, lam, per_press, it, done)

    def _flexibility(self, g: PressGeometry) -> np.ndarray:
        """Σ_j w_j² aᵀ diag(A_j)⁻¹ a per candidate probe: its compliance if its nodes were alone."""
        slots = self.probe_slots[g.probes]
        w = self.probe_weights[g.probes]
        inv = np.vstack([(1.0 / self.k_diag).reshape(-1, 3), np.zeros((1, 3))])[slots]  # (k, 3 nodes, 3)
        f = np.einsum("pj,pjc,c->p", w**2, inv, g.press.axis**2)
        flex: np.ndarray = np.maximum(f, 1e-300)
        return flex

    def _objective(self, x: np.ndarray, q: np.ndarray, r: np.ndarray, geoms: list[PressGeometry],
                   depths: list[float], k_pen: list[np.ndarray]) -> float:
        """½xᵀAx − rᵀx + Σ ½k max(0, penetration)² − Σ F d: what the contact solution minimises."""
        j = 0.5 * float(x @ q) - 0.5 * float(r @ x)
        for g, d, k in zip(geoms, depths, k_pen, strict=True):
            if not g.probes.size:
                continue
            pen = np.maximum(-self._gaps(x, g, d), 0.0)
            j += 0.5 * float(k @ pen**2)
            if g.press.force_n:
                j -= g.press.force_n * d
        return j

    def _gaps(self, x: np.ndarray, g: PressGeometry, depth: float) -> np.ndarray:
        """a·u(p) − (d − φ_p) for every candidate probe: negative means penetration."""
        xn = np.vstack([x.reshape(-1, 3), np.zeros((1, 3))])  # slot −1 reads the zero row
        up = np.einsum("pk,pkc->pc", self.probe_weights[g.probes], xn[self.probe_slots[g.probes]])
        gaps: np.ndarray = up @ g.press.axis - (depth - g.phi)
        return gaps

    def _assemble(self, x: np.ndarray, nodal: np.ndarray, geoms: list[PressGeometry],
                  live_index: dict[int, int], rows: _Rows, lam: np.ndarray,
                  per_press: dict[int, tuple[float, np.ndarray]], iterations: int,
                  converged: bool) -> ContactResult:
        """``nodal``: Bᵀλ, the contact forces on every dof (the last Newton step has it)."""
        forces: list[np.ndarray] = []
        depths: list[float] = []
        active: list[np.ndarray] = []
        for k, g in enumerate(geoms):
            if k not in live_index:
                forces.append(np.zeros(3))
                depths.append(g.first_touch_depth if g.press.depth_mm is None else g.press.depth_mm)
                active.append(np.empty(0, dtype=np.int64))
                continue
            sel = rows.press == live_index[k]
            forces.append((lam[sel, None] * rows.direction[sel]).sum(axis=0))
            d, probes = per_press[k]
            depths.append(float(d))
            active.append(np.sort(probes))
        return ContactResult(x, np.asarray(nodal), tuple(forces), tuple(depths), tuple(active),
                             iterations, converged)

    # -- one equality-constrained solve ---------------------------------------------------
    def _equality_solve(
        self, r: np.ndarray, x0: np.ndarray, geoms: list[PressGeometry], active: list[np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, list[float], _Rows]:
        rows = _Rows.build(geoms, active, self.probe_slots, self.probe_weights)
        m = rows.count
        force_presses = [k for k, g in enumerate(geoms) if g.press.force_n is not None]
        depths = [g.press.depth_mm if g.press.depth_mm is not None else math.nan for g in geoms]
        if m == 0:
            for k in force_presses:
                depths[k] = geoms[k].first_touch_depth
            return x0, np.zeros(0), depths, rows
        e = np.zeros((m, len(force_presses)))
        for j, k in enumerate(force_presses):
            e[(rows.press == k) & rows.is_normal, j] = 1.0
        f_target = np.array([geoms[k].press.force_n for k in force_presses], dtype=float)
        g0 = rows.target.copy()
        for k, g in enumerate(geoms):
            if g.press.depth_mm is not None:
                g0[(rows.press == k) & rows.is_normal] += g.press.depth_mm
        dofs, bd = rows.dense()
        if self.diagonal or 2 * len(dofs) * self.n * 8 <= self.cache_bytes:
            x, lam, d = self._schur(x0, dofs, bd, g0, e, f_target)
        else:
            x, lam, d = self._kkt(r, rows.matrix(self.n), g0, e, f_target)
        for j, k in enumerate(force_presses):
            depths[k] = float(d[j])
        return x, lam, depths, rows

    def _schur(self, x0: np.ndarray, dofs: np.ndarray, bd: np.ndarray, g0: np.ndarray, e: np.ndarray,
               f_target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """B restricted to the touched dofs is the small dense ``bd`` (m x len(dofs))."""
        if self.diagonal:
            z_touched = bd.T / self.d[dofs][:, None]  # A⁻¹Bᵀ is zero off the touched dofs
            bz = bd @ z_touched
        else:
            cols = self.node_columns(dofs[::3] // 3)  # (n, len(dofs)): A⁻¹ restricted to those columns
            bz = bd @ cols[dofs] @ bd.T
        bz = 0.5 * (bz + bz.T)
        m, nf = e.shape
        lhs = np.zeros((m + nf, m + nf))
        flex = (bd**2) @ (1.0 / self.k_diag[dofs])  # the same penalty compliance as _flexibility
        lhs[:m, :m] = bz + np.diag(REGULARISATION * np.maximum(flex, 1e-300))
        lhs[:m, m:] = -e
        lhs[m:, :m] = e.T
        rhs = np.concatenate([g0 - bd @ x0[dofs], f_target])
        try:
            sol = np.linalg.solve(lhs, rhs)
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
        lam, d = sol[:m], sol[m:]
        if self.diagonal:
            x = x0.copy()
            x[dofs] += z_touched @ lam
        else:
            x = x0 + cols @ (bd.T @ lam)
        return x, lam, d

    def _kkt(self, r: np.ndarray, b: sp.csr_matrix, g0: np.ndarray, e: np.ndarray,
             f_target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n, m = self.n, b.shape[0]
        # the diagonal of BA⁻¹Bᵀ, estimated from A's diagonal, scales the regularisation
        flex = np.asarray(b.multiply(b) @ (1.0 / self.k_diag)).ravel()
        es = sp.csr_matrix(e)
        kkt = sp.bmat([[self.a, -b.T, None], [b, sp.diags(REGULARISATION * flex), -es], [None, es.T, None]],
                      format="csc")
        sol: np.ndarray = splu(kkt).solve(np.concatenate([r, g0, f_target]))
        return sol[:n], sol[n : n + m], sol[n + m :]


@dataclass(frozen=True, slots=True, eq=False)
class _Rows:
    """The contact rows of an active set: probe, its nodes and weights, direction, target, press."""

    probe: np.ndarray  # (m,)
    slots: np.ndarray  # (m, 3) model slots, −1 for none
    weights: np.ndarray  # (m, 3)
    direction: np.ndarray  # (m, 3)
    target: np.ndarray  # (m,) right-hand side without the press depth
    press: np.ndarray  # (m,) press index
    is_normal: np.ndarray  # (m,) bool

    @property
    def count(self) -> int:
        return len(self.probe)

    def matrix(self, n: int) -> sp.csr_matrix:
        """B (m x n): row r is Σ_j w_rj dir_rᵀ on the dofs of node j."""
        m = self.count
        ok = (self.slots >= 0) & (self.weights != 0)
        r_idx, j_idx = np.nonzero(ok)
        rows = np.repeat(r_idx, 3)
        cols = (3 * self.slots[r_idx, j_idx][:, None] + np.arange(3)).ravel()
        vals = (self.weights[r_idx, j_idx][:, None] * self.direction[r_idx]).ravel()
        return sp.csr_matrix((vals, (rows, cols)), shape=(m, n))

    def nodal(self, n: int, lam: np.ndarray) -> np.ndarray:
        """Bᵀλ: the contact forces on every dof."""
        out = np.zeros(n)
        if self.count:
            dofs, bd = self.dense()
            out[dofs] = bd.T @ lam
        return out

    def dense(self) -> tuple[np.ndarray, np.ndarray]:
        """(touched dofs, B restricted to them as a dense m x len(dofs) array)."""
        ok = (self.slots >= 0) & (self.weights != 0)
        nodes = np.unique(self.slots[ok])
        dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
        bd = np.zeros((self.count, len(dofs)))
        r_idx, j_idx = np.nonzero(ok)  # a probe's weighted nodes are distinct: no repeated entries
        col = 3 * np.searchsorted(nodes, self.slots[r_idx, j_idx])
        vals = self.weights[r_idx, j_idx][:, None] * self.direction[r_idx]
        for c in range(3):
            bd[r_idx, col + c] = vals[:, c]
        return dofs, bd

    @classmethod
    def empty(cls) -> _Rows:
        z = np.zeros(0, dtype=np.int64)
        return cls(z, np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), z,
                   np.zeros(0, bool))

    @classmethod
    def build(cls, geoms: list[PressGeometry], active: list[np.ndarray], probe_slots: np.ndarray,
              probe_weights: np.ndarray) -> _Rows:
        probe: list[np.ndarray] = []
        direction: list[np.ndarray] = []
        target: list[np.ndarray] = []
        press: list[np.ndarray] = []
        normal: list[np.ndarray] = []
        for k, (g, act) in enumerate(zip(geoms, active, strict=True)):
            if act.size == 0:
                continue
            p = g.probes[act]
            probe.append(p)
            direction.append(np.broadcast_to(g.press.axis, (len(p), 3)))
            target.append(-g.phi[act])
            press.append(np.full(len(p), k))
            normal.append(np.ones(len(p), bool))
            if g.press.sticks:
                for t in g.tangents:
                    probe.append(p)
                    direction.append(np.broadcast_to(t, (len(p), 3)))
                    target.append(np.full(len(p), float(g.press.shear_mm @ t)))
                    press.append(np.full(len(p), k))
                    normal.append(np.zeros(len(p), bool))
        if not probe:
            return cls.empty()
        pr = np.concatenate(probe).astype(np.int64)
        return cls(pr, probe_slots[pr], probe_weights[pr], np.concatenate(direction).astype(float),
                   np.concatenate(target).astype(float), np.concatenate(press), np.concatenate(normal))


def _claim_unique(geoms: list[PressGeometry], active: list[np.ndarray], n_probes: int) -> None:
    """A probe belongs to at most one press (two equal rows would make the system singular)."""
    claimed = np.zeros(n_probes, dtype=bool)
    for k, g in enumerate(geoms):
        active[k] = active[k][~claimed[g.probes[active[k]]]]
        claimed[g.probes[active[k]]] = True
