"""Scripted scenes: what touches a simulated skin, where, how hard and when.

A scene is a TOML file (see docs/scenes.md)::

    [scene]
    name = "demo"
    loop = true            # replay forever (the demo); false ends the device
    material = "ecoflex-00-30"

    [[step]]
    kind = "press"         # press | tap | slide | pinch
    at = [0.0, 53.0, 130.0]  # mm, device frame; snapped to the nearest skin node
    start_s = 0.5
    duration_s = 1.0
    depth_mm = 3.0
    radius_mm = 6.0

A ``slide`` also has ``to`` (end point); a ``pinch`` has ``at`` and ``to`` as the
two fingers' start points, moving towards each other by ``approach_mm``. Depth
ramps in and out over ``ramp_s``. Times are seconds from the scene start.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wott_hub.tactile.indentation import Indenter, indent, nearest_node
from wott_hub.tactile.mesh import SkinMesh

__all__ = ["Scene", "SceneError", "Step"]

KINDS = ("press", "tap", "slide", "pinch")


class SceneError(ValueError):
    """A scene file that cannot be played, with the step and field at fault."""


@dataclass(frozen=True, slots=True)
class Step:
    kind: str
    at: np.ndarray
    start_s: float
    duration_s: float
    depth_mm: float
    radius_mm: float = 5.0
    ramp_s: float = 0.05
    to: np.ndarray | None = None
    approach_mm: float = 10.0
    shear_mm: float = 0.0

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def depth_at(self, t: float) -> float:
        """Trapezoidal depth profile: ramp in, hold, ramp out."""
        if not self.start_s <= t <= self.end_s:
            return 0.0
        ramp = min(self.ramp_s, self.duration_s / 2)
        if ramp <= 0:
            return self.depth_mm
        u = min(t - self.start_s, self.end_s - t) / ramp
        return self.depth_mm * min(1.0, u)


@dataclass(frozen=True)
class Scene:
    name: str
    steps: tuple[Step, ...]
    loop: bool = False
    material: str = "ecoflex-00-30"
    model: str = "indentation"  # "kelvin-voigt" once the mechanics module is chosen

    @property
    def duration_s(self) -> float:
        return max((s.end_s for s in self.steps), default=0.0) + 0.25  # rest tail

    @classmethod
    def load(cls, path: str | Path) -> Scene:
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text())
        except (OSError, tomllib.TOMLDecodeError) as e:
            raise SceneError(f"{path}: {e}") from e
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<scene>") -> Scene:
        head = data.get("scene", {})
        steps = []
        for i, raw in enumerate(data.get("step", [])):
            where = f"{source}: step[{i}]"
            kind = raw.get("kind")
            if kind not in KINDS:
                raise SceneError(f"{where}.kind: {kind!r} is not one of {', '.join(KINDS)}")
            try:
                at = _point(raw["at"], f"{where}.at")
                to = _point(raw["to"], f"{where}.to") if "to" in raw else None
                step = Step(
                    kind=kind,
                    at=at,
                    to=to,
                    start_s=float(raw.get("start_s", 0.0)),
                    duration_s=float(raw.get("duration_s", 0.15 if kind == "tap" else 1.0)),
                    depth_mm=float(raw.get("depth_mm", 2.0)),
                    radius_mm=float(raw.get("radius_mm", 5.0)),
                    ramp_s=float(raw.get("ramp_s", 0.03 if kind == "tap" else 0.1)),
                    approach_mm=float(raw.get("approach_mm", 10.0)),
                    shear_mm=float(raw.get("shear_mm", 0.0)),
                )
            except KeyError as e:
                raise SceneError(f"{where}: missing field {e.args[0]!r}") from None
            except (TypeError, ValueError) as e:
                raise SceneError(f"{where}: {e}") from None
            if kind in ("slide", "pinch") and step.to is None:
                raise SceneError(f"{where}.to: a {kind} needs an end point 'to'")
            for name in ("duration_s", "depth_mm", "radius_mm"):
                v = getattr(step, name)
                if not (np.isfinite(v) and v > 0):
                    raise SceneError(f"{where}.{name}: must be a positive number, got {v}")
            if step.start_s < 0 or step.ramp_s < 0:
                raise SceneError(f"{where}: start_s and ramp_s must not be negative")
            steps.append(step)
        return cls(
            name=str(head.get("name", Path(source).stem)),
            steps=tuple(steps),
            loop=bool(head.get("loop", False)),
            material=str(head.get("material", "ecoflex-00-30")),
            model=str(head.get("model", "indentation")),
        )

    def indenters_at(self, t: float, mesh: SkinMesh) -> list[Indenter]:
        """The indenters touching the skin at scene time ``t`` (seconds)."""
        if self.loop and self.duration_s > 0:
            t = t % self.duration_s
        out = []
        for s in self.steps:
            depth = s.depth_at(t)
            if depth <= 0:
                continue
            u = (t - s.start_s) / s.duration_s
            if s.kind == "slide":
                a, b = _on_surface(mesh, s.at), _on_surface(mesh, s.to)
                centre = _on_surface(mesh, a + u * (b - a))
                direction = (b - a) / max(np.linalg.norm(b - a), 1e-9)
                drag = s.shear_mm * depth / s.depth_mm  # shear ramps in and out with the depth
                out.append(Indenter(centre, depth, s.radius_mm, drag * direction))
            elif s.kind == "pinch":
                a, b = _on_surface(mesh, s.at), _on_surface(mesh, s.to)
                gap = np.linalg.norm(b - a)
                step = min(u * s.approach_mm, gap) / 2 / max(gap, 1e-9)
                out.append(Indenter(_on_surface(mesh, a + step * (b - a)), depth, s.radius_mm))
                out.append(Indenter(_on_surface(mesh, b + step * (a - b)), depth, s.radius_mm))
            else:
                out.append(Indenter(_on_surface(mesh, s.at), depth, s.radius_mm))
        return out

    def displacement_at(self, t: float, mesh: SkinMesh) -> np.ndarray:
        """Ground-truth displacement (N x 3, mm) at scene time ``t``."""
        return indent(mesh, self.indenters_at(t, mesh))


def _point(value: Any, where: str) -> np.ndarray:
    p = np.asarray(value, dtype=float)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise SceneError(f"{where}: expected [x, y, z] in mm, got {value!r}")
    return p


def _on_surface(mesh: SkinMesh, point: np.ndarray) -> np.ndarray:
    """Project a point onto the tangent plane of its nearest node: smooth paths, on the skin."""
    k = nearest_node(mesh, point)
    n = mesh.normals[k]
    return point - ((point - mesh.nodes[k]) @ n) * n
