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

With ``model = "kelvin-voigt"`` the ground truth comes from the skin mechanics
(``wott_hub.tactile.mechanics``, docs/mechanics.md): the scene's ``material``
sets the modulus, ``thickness_mm`` (default 3), ``refine`` (mesh subdivision
levels, default 0) and an optional inline table ``skin`` (``SkinParams``
fields, e.g. ``{backed = true}``) the rest. Steps may then give ``force_n``
instead of ``depth_mm`` and ``indenter = "flat"`` for a flat punch.
"""

from __future__ import annotations

import math
import tomllib
import weakref
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from wott_hub.tactile.indentation import Indenter, indent, nearest_node
from wott_hub.tactile.materials import MATERIALS
from wott_hub.tactile.mesh import SkinMesh

if TYPE_CHECKING:  # the mechanics load only for kelvin-voigt scenes
    from wott_hub.tactile.mechanics import Press, QuasiStatic

__all__ = ["Scene", "SceneError", "SceneSimulator", "Step"]

KINDS = ("press", "tap", "slide", "pinch")
MODELS = ("indentation", "kelvin-voigt")
INDENTERS = ("sphere", "flat")


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
    force_n: float | None = None  # force-controlled instead of depth (kelvin-voigt scenes only)
    indenter: str = "sphere"  # sphere | flat (kelvin-voigt scenes only)

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def level_at(self, t: float) -> float:
        """Trapezoidal profile in [0, 1]: ramp in, hold, ramp out."""
        if not self.start_s <= t <= self.end_s:
            return 0.0
        ramp = min(self.ramp_s, self.duration_s / 2)
        if ramp <= 0:
            return 1.0
        return min(1.0, min(t - self.start_s, self.end_s - t) / ramp)

    def depth_at(self, t: float) -> float:
        return self.depth_mm * self.level_at(t)


@dataclass(frozen=True)
class Scene:
    name: str
    steps: tuple[Step, ...]
    loop: bool = False
    material: str = "ecoflex-00-30"
    model: str = "indentation"  # or "kelvin-voigt": ground truth from wott_hub.tactile.mechanics
    thickness_mm: float = 3.0
    refine: int = 0
    skin: dict[str, Any] = field(default_factory=dict, compare=False)
    _simulators: Any = field(default_factory=weakref.WeakKeyDictionary, compare=False, repr=False)

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
                    force_n=float(raw["force_n"]) if "force_n" in raw else None,
                    indenter=str(raw.get("indenter", "sphere")),
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
            if step.force_n is not None and not (math.isfinite(step.force_n) and step.force_n >= 0):
                raise SceneError(f"{where}.force_n: must be a number >= 0 N, got {step.force_n}")
            if step.indenter not in INDENTERS:
                raise SceneError(f"{where}.indenter: {step.indenter!r} is not one of {', '.join(INDENTERS)}")
            steps.append(step)
        model = str(head.get("model", "indentation"))
        material = str(head.get("material", "ecoflex-00-30"))
        if model not in MODELS:
            raise SceneError(f"{source}: scene.model: {model!r} is not one of {', '.join(MODELS)}")
        if model == "kelvin-voigt" and material not in MATERIALS:
            raise SceneError(f"{source}: scene.material: {material!r} is not one of {', '.join(MATERIALS)}")
        if model != "kelvin-voigt":
            for i, st in enumerate(steps):
                if st.force_n is not None:
                    raise SceneError(f"{source}: step[{i}].force_n: force-controlled steps need "
                                     "model = \"kelvin-voigt\"")
        skin = head.get("skin", {})
        if not isinstance(skin, dict):
            raise SceneError(f"{source}: scene.skin: expected a table of skin parameters, got {skin!r}")
        try:
            thickness = float(head.get("thickness_mm", 3.0))
            refine = int(head.get("refine", 0))
        except (TypeError, ValueError) as e:
            raise SceneError(f"{source}: scene: {e}") from None
        if not (math.isfinite(thickness) and thickness > 0) or not 0 <= refine <= 3:
            raise SceneError(f"{source}: scene: thickness_mm must be positive and refine in 0..3")
        return cls(
            name=str(head.get("name", Path(source).stem)),
            steps=tuple(steps),
            loop=bool(head.get("loop", False)),
            material=material,
            model=model,
            thickness_mm=thickness,
            refine=refine,
            skin=dict(skin),
        )

    def _scene_time(self, t: float) -> float:
        return t % self.duration_s if self.loop and self.duration_s > 0 else t

    def touching(self, t: float) -> bool:
        """Whether any indenter touches the skin at scene time ``t``: a few µs, against tens of
        µs for ``indenters_at`` (which places each indenter on the mesh)."""
        t = self._scene_time(t)
        return any(s.level_at(t) > 0 for s in self.steps)

    def _touches(self, t: float, mesh: SkinMesh) -> Iterator[tuple[Step, float, np.ndarray, np.ndarray]]:
        """(step, level, centre, shear) of every indenter touching the skin at scene time ``t``."""
        t = self._scene_time(t)
        for s in self.steps:
            level = s.level_at(t)
            if level <= 0:
                continue
            u = (t - s.start_s) / s.duration_s
            to = s.to  # a slide's and a pinch's, checked by from_dict
            if s.kind == "slide" and to is not None:
                a, b = _on_surface(mesh, s.at), _on_surface(mesh, to)
                centre = _on_surface(mesh, a + u * (b - a))
                direction = (b - a) / max(np.linalg.norm(b - a), 1e-9)
                drag = s.shear_mm * level  # shear ramps in and out with the depth
                yield s, level, centre, drag * direction
            elif s.kind == "pinch" and to is not None:
                a, b = _on_surface(mesh, s.at), _on_surface(mesh, to)
                gap = float(np.linalg.norm(b - a))
                step = min(u * s.approach_mm, gap) / 2 / max(gap, 1e-9)
                yield s, level, _on_surface(mesh, a + step * (b - a)), np.zeros(3)
                yield s, level, _on_surface(mesh, b + step * (a - b)), np.zeros(3)
            else:
                yield s, level, _on_surface(mesh, s.at), np.zeros(3)

    def indenters_at(self, t: float, mesh: SkinMesh) -> list[Indenter]:
        """The indenters touching the skin at scene time ``t`` (seconds)."""
        return [Indenter(centre, s.depth_mm * level if s.force_n is None else 0.0, s.radius_mm, shear)
                for s, level, centre, shear in self._touches(t, mesh)]

    def presses_at(self, t: float, mesh: SkinMesh) -> list[Press]:
        """The same indenters as mechanics presses (sphere or flat punch, by depth or by force)."""
        from wott_hub.tactile.mechanics import FlatPunch, Sphere, press_on

        out: list[Press] = []
        for s, level, centre, shear in self._touches(t, mesh):
            shape = FlatPunch(s.radius_mm) if s.indenter == "flat" else Sphere(s.radius_mm)
            sticky = shear if s.shear_mm > 0 else None
            if s.force_n is None:
                out.append(press_on(mesh, centre, shape, depth_mm=s.depth_mm * level, shear_mm=sticky))
            else:
                out.append(press_on(mesh, centre, shape, force_n=s.force_n * level, shear_mm=sticky))
        return out

    def displacement_at(self, t: float, mesh: SkinMesh) -> np.ndarray:
        """Ground-truth displacement (N x 3, mm) at scene time ``t``.

        The Kelvin-Voigt model is solved quasi-statically here (a pure function
        of t, like the indentation model); ``SceneSimulator`` steps it in time.
        Nothing touching costs nothing: the skin is at rest in both models.
        """
        if not self.touching(t):
            return np.zeros_like(mesh.nodes)
        if self.model != "kelvin-voigt":
            return indent(mesh, self.indenters_at(t, mesh))
        sim: SceneSimulator | None = self._simulators.get(mesh)
        if sim is None:
            sim = self._simulators[mesh] = SceneSimulator(self, mesh)
        return sim.displacement_at(t)


class SceneSimulator:
    """Ground truth of a scene on a Kelvin-Voigt skin, frame after frame.

    ``integrator`` is "quasi-static" (the steady state at each frame: no
    history, about a millisecond a frame on the 707-node barrel) or
    "backward-euler" (one implicit step per frame with a cached factorisation:
    the skin's damping lag and inertia). A time before the last one, or more
    than a second after it, restarts from the settled state. ``contact_forces``
    are the indenters' forces on the skin (N) at the last frame: the truth a
    force estimator is scored against.
    """

    def __init__(self, scene: Scene, mesh: SkinMesh, *, integrator: str = "quasi-static",
                 thickness_mm: float | None = None, frame_rate_hz: float = 120.0,
                 refine: int | None = None, **skin: Any) -> None:
        from wott_hub.tactile.mechanics import (
            MechanicsError,
            QuasiStatic,
            SkinModel,
            make_integrator,
            subdivide,
        )

        self.scene, self.mesh = scene, mesh
        try:
            fine = subdivide(mesh, scene.refine if refine is None else refine)
            self.model = SkinModel.from_material(fine, MATERIALS[scene.material],
                                                 thickness_mm or scene.thickness_mm, **(scene.skin | skin))
            self.integrator = make_integrator(integrator, self.model)
        except (MechanicsError, TypeError) as e:
            raise SceneError(f"scene {scene.name!r}: {e}") from None
        h = self.model.params.thickness_mm
        if self.model.params.backed:
            for i, s in enumerate(scene.steps):
                if s.force_n is None and s.depth_mm >= h:
                    raise SceneError(f"scene {scene.name!r}: step[{i}].depth_mm: {s.depth_mm} mm is deeper "
                                     f"than the {h:g} mm skin over its rigid backing")
        self.frame_s = 1.0 / frame_rate_hz
        integ = self.integrator
        self._static: QuasiStatic = integ if isinstance(integ, QuasiStatic) else QuasiStatic(self.model)
        self.state = self._static.solve([], t=0.0)

    @property
    def contact_forces(self) -> list[np.ndarray]:
        return list(self.state.forces)

    def displacement_at(self, t: float) -> np.ndarray:
        """(N, 3) displacement of the device mesh's nodes at scene time ``t``, mm."""
        def presses(tt: float) -> list[Press]:
            return self.scene.presses_at(tt, self.mesh)

        if self.integrator is self._static:
            self.state = self._static.solve(presses(t), t=t, warm=self.state)
        else:
            lag = t - self.state.t
            if lag < -0.5 * self.frame_s or lag > 1.0:  # back in time or a long gap: start settled
                self.state = self._static.solve(presses(t), t=t)
            elif lag > 0.5 * self.frame_s:
                for _ in range(max(1, round(lag / self.frame_s))):
                    self.state = self.integrator.step(self.state, self.frame_s, presses)
        return self.model.to_nodes(self.state.u)[: self.mesh.n_nodes]


def _point(value: Any, where: str) -> np.ndarray:
    p = np.asarray(value, dtype=float)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise SceneError(f"{where}: expected [x, y, z] in mm, got {value!r}")
    return p


def _on_surface(mesh: SkinMesh, point: np.ndarray) -> np.ndarray:
    """Project a point onto the tangent plane of its nearest node: smooth paths, on the skin."""
    k = nearest_node(mesh, point)
    n = mesh.normals[k]
    on_plane: np.ndarray = point - ((point - mesh.nodes[k]) @ n) * n
    return on_plane
