"""Rigid indenters and how they meet the skin.

An indenter is a shape (a sphere or a flat cylindrical punch) whose tip moves
along a press ``axis`` (a unit vector pointing into the skin) from a ``point``
on the rest surface. It is driven either to a depth (the tip's distance past
the point along the axis) or with a force (the depth is then an unknown that
the solver finds). A ``shear_mm`` vector, when given, makes the contact stick:
every node under the indenter is also carried tangentially by that offset.
Without it the contact is frictionless.

Contact is by projection, linearised like the rest of the model: a candidate
node i (under the indenter's footprint, on the side of the skin facing it)
must satisfy  a·u_i ≥ d − φ_i,  with φ_i = a·(X_i − P) + s(r_i) its rest height
above the tip plus the shape's setback s at its lateral distance r_i from the
axis, both taken at rest. The constraint direction is the press axis rather
than the local surface normal of the indenter, which is exact for a punch and
for the sphere's apex and errs by the slope (r/R) on the sphere's flanks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..indentation import nearest_node
from ..mesh import SkinMesh
from .model import ContactError, MechanicsError, SkinModel

__all__ = ["FlatPunch", "Press", "PressGeometry", "Sphere", "press_geometry", "press_on"]


@dataclass(frozen=True, slots=True)
class Sphere:
    radius_mm: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius_mm) and self.radius_mm > 0):
            raise MechanicsError(f"sphere radius must be a positive number of mm, got {self.radius_mm}")

    def setback(self, r: np.ndarray) -> np.ndarray:
        """How far behind the tip the surface is at lateral distance r (inf outside)."""
        big_r = self.radius_mm
        inside = r < big_r
        out = np.full(r.shape, np.inf)
        out[inside] = big_r - np.sqrt(big_r**2 - r[inside] ** 2)
        return out

    @property
    def footprint_mm(self) -> float:
        return self.radius_mm


@dataclass(frozen=True, slots=True)
class FlatPunch:
    radius_mm: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius_mm) and self.radius_mm > 0):
            raise MechanicsError(f"punch radius must be a positive number of mm, got {self.radius_mm}")

    def setback(self, r: np.ndarray) -> np.ndarray:
        return np.where(r <= self.radius_mm, 0.0, np.inf)

    @property
    def footprint_mm(self) -> float:
        return self.radius_mm


@dataclass(frozen=True, slots=True, eq=False)
class Press:
    """One indenter at one instant: where, along which axis, how deep or how hard."""

    shape: Sphere | FlatPunch
    point: np.ndarray
    axis: np.ndarray
    depth_mm: float | None = None
    force_n: float | None = None
    shear_mm: np.ndarray | None = None

    def __post_init__(self) -> None:
        point = np.asarray(self.point, dtype=float)
        axis = np.asarray(self.axis, dtype=float)
        if point.shape != (3,) or not np.isfinite(point).all():
            raise MechanicsError(f"press point must be a finite [x, y, z], got {self.point!r}")
        norm = float(np.linalg.norm(axis)) if axis.shape == (3,) and np.isfinite(axis).all() else 0.0
        if norm < 1e-12:
            raise MechanicsError(f"press axis must be a finite non-zero vector, got {self.axis!r}")
        if (self.depth_mm is None) == (self.force_n is None):
            raise MechanicsError("a press needs exactly one of depth_mm and force_n")
        if self.depth_mm is not None and not math.isfinite(self.depth_mm):
            raise MechanicsError(f"press depth must be finite, got {self.depth_mm}")
        if self.force_n is not None and not (math.isfinite(self.force_n) and self.force_n >= 0):
            raise MechanicsError(f"press force must be a finite number >= 0 N (an indenter cannot pull), "
                                 f"got {self.force_n}")
        axis = axis / norm
        shear = None
        if self.shear_mm is not None:
            s = np.asarray(self.shear_mm, dtype=float)
            if s.shape != (3,) or not np.isfinite(s).all():
                raise MechanicsError(f"shear must be a finite [x, y, z] in mm, got {self.shear_mm!r}")
            shear = s - (s @ axis) * axis
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "shear_mm", shear)

    @property
    def sticks(self) -> bool:
        return self.shear_mm is not None


def press_on(
    model_or_mesh: SkinModel | SkinMesh,
    point: npt.ArrayLike,
    shape: Sphere | FlatPunch,
    *,
    depth_mm: float | None = None,
    force_n: float | None = None,
    shear_mm: npt.ArrayLike | None = None,
) -> Press:
    """A press at the skin point nearest ``point``, along the inward normal there."""
    mesh = model_or_mesh.mesh if isinstance(model_or_mesh, SkinModel) else model_or_mesh
    p = np.asarray(point, dtype=float)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise MechanicsError(f"press point must be a finite [x, y, z], got {point!r}")
    k = nearest_node(mesh, p)
    n = mesh.normals[k]
    if not np.linalg.norm(n) > 0.5:
        raise MechanicsError(f"node {k} nearest to {p.tolist()} has no surface normal (it is in no cell)")
    on_plane = p - ((p - mesh.nodes[k]) @ n) * n
    shear = None if shear_mm is None else np.asarray(shear_mm)  # Press checks its shape and values
    return Press(shape, on_plane, -n, depth_mm=depth_mm, force_n=force_n, shear_mm=shear)


@dataclass(frozen=True, slots=True, eq=False)
class PressGeometry:
    """A press resolved against a model: the probes it may touch and their offsets."""

    press: Press
    probes: np.ndarray  # candidate probe indices (model.probes), ascending
    phi: np.ndarray  # (k,) constraint offsets: a·u(probe) >= d - phi
    tangents: np.ndarray  # (2, 3) orthonormal basis across the axis

    @property
    def first_touch_depth(self) -> float:
        """Depth at which the indenter first reaches a candidate (inf if none)."""
        return float(self.phi.min()) if self.phi.size else math.inf

    def with_press(self, press: Press) -> PressGeometry:
        return PressGeometry(press, self.probes, self.phi, self.tangents)


def _tangents(a: np.ndarray) -> np.ndarray:
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    t1 = np.cross(a, helper)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(a, t1)])


def press_geometry(model: SkinModel, press: Press) -> PressGeometry:
    """Candidate probes of ``press``: under its footprint, facing it, and able to move."""
    a = press.axis
    pr = model.probes
    p = model.params
    reach = press.shape.footprint_mm + 2 * p.thickness_mm + 3 * model.probe_edge_mm + (
        max(press.depth_mm, 0.0) if press.depth_mm is not None else 10 * p.thickness_mm)
    near = np.asarray(model.probe_tree.query_ball_point(press.point, reach), dtype=np.int64)
    near.sort()
    rel = pr.rest[near] - press.point
    along = rel @ a
    lateral = rel - along[:, None] * a
    r = np.sqrt(np.einsum("ij,ij->i", lateral, lateral))
    facing = pr.normals[near] @ a <= 1e-9
    cand = np.flatnonzero((r < press.shape.footprint_mm) & facing & model.probe_moves[near])
    phi = along[cand] + press.shape.setback(r[cand])
    keep = np.isfinite(phi)
    return PressGeometry(press, near[cand[keep]], phi[keep], _tangents(a))


def check_depth(model: SkinModel, press: Press, depth_mm: float) -> None:
    """Refuse a press through a backed skin: it would crush the layer against its backing."""
    h = model.params.thickness_mm
    if model.params.backed and depth_mm >= h:
        how = f"a {press.force_n:g} N press needs {depth_mm:.3g} mm" if press.force_n is not None else (
            f"a {depth_mm:.3g} mm press")
        raise ContactError(f"{how}: deeper than the {h:g} mm skin over its rigid backing "
                           f"(at {np.round(press.point, 3).tolist()})")
