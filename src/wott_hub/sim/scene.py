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

The file is declared once (``SceneFile``, read through ``wott_hub.configspec`` like
the hub's own config): a key it does not declare, a value of the wrong type or out
of its bounds (NaN and infinities included) is a ``SceneError`` (a ``ConfigError``)
naming the file, step and key: ``scene.toml: step[2].to: a slide needs an end point
'to'``.
"""

from __future__ import annotations

import tomllib
import weakref
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import msgspec
import numpy as np

from wott_hub.configspec import Flag, Model, bounded, read, says
from wott_hub.errors import ConfigError
from wott_hub.tactile.indentation import Indenter, indent, nearest_node
from wott_hub.tactile.materials import MATERIALS
from wott_hub.tactile.mesh import SkinMesh

if TYPE_CHECKING:  # the mechanics load only for kelvin-voigt scenes
    from wott_hub.tactile.mechanics import Press, QuasiStatic

__all__ = ["Scene", "SceneError", "SceneFile", "SceneSimulator", "Step"]


class SceneError(ConfigError):
    """A scene file that cannot be played, with the step and field at fault."""


# -- the file, declared once (wott_hub.configspec): its check, defaults and error text ------------

Coordinate = Annotated[float, bounded("a coordinate in mm", ge=-1e4, le=1e4)]
Point = Annotated[tuple[Coordinate, Coordinate, Coordinate], says("a point [x, y, z] in mm")]
Time = Annotated[float, bounded("a time in seconds from the scene start", ge=0, le=1e7)]
Ramp = Annotated[float, bounded("a number of seconds (0: at once)", ge=0, le=1e7)]
Duration = Annotated[float, bounded("a positive number of seconds", gt=0, le=1e7)]
Length = Annotated[float, bounded("a positive number of mm", gt=0, le=1e4)]
Distance = Annotated[float, bounded("a distance in mm", ge=-1e4, le=1e4)]


class StepTable(Model):
    """A ``[[step]]`` table. ``duration_s`` and ``ramp_s`` default by ``kind`` (a tap is short)."""

    kind: Literal["press", "tap", "slide", "pinch"]
    at: Point
    to: Point | None = None
    start_s: Time = 0.0
    duration_s: Duration | None = None  # 1.0, a tap 0.15
    depth_mm: Length = 2.0
    radius_mm: Length = 5.0
    ramp_s: Ramp | None = None  # 0.1, a tap 0.03
    approach_mm: Distance = 10.0
    shear_mm: Distance = 0.0
    force_n: Annotated[float, bounded("a force in N", ge=0, le=1e5)] | None = None
    indenter: Literal["sphere", "flat"] = "sphere"


class SceneTable(Model):
    """The ``[scene]`` table; ``name`` defaults to the file's name."""

    name: Annotated[str, says("a string")] | None = None
    loop: Flag = False
    material: Annotated[str, says("a material name (wott_hub.tactile.MATERIALS)")] = "ecoflex-00-30"
    model: Literal["indentation", "kelvin-voigt"] = "indentation"
    thickness_mm: Annotated[float, bounded("a positive number of mm", gt=0, le=1e3)] = 3.0
    refine: Annotated[int, says("a number of subdivision levels", ge=0, le=3)] = 0
    skin: Annotated[dict[str, Any], says("a table of skin parameters")] = msgspec.field(default_factory=dict)


class SceneFile(Model):
    """A whole scene file: ``[scene]`` and its ``[[step]]`` tables."""

    scene: SceneTable = msgspec.field(default_factory=SceneTable)
    step: list[StepTable] = msgspec.field(default_factory=list)


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
        """The scene of a parsed file; a ``SceneError`` names ``source``, the table and the key."""
        f: SceneFile = read(SceneFile, data, f"{source}: ", error=SceneError)
        head = f.scene
        if head.model == "kelvin-voigt" and head.material not in MATERIALS:
            raise SceneError(f"{source}: scene.material: {head.material!r} is not one of "
                             f"{', '.join(MATERIALS)}")
        steps = []
        for i, raw in enumerate(f.step):
            where = f"{source}: step[{i}]"
            if raw.kind in ("slide", "pinch") and raw.to is None:
                raise SceneError(f"{where}.to: a {raw.kind} needs an end point 'to'")
            if raw.force_n is not None and head.model != "kelvin-voigt":
                raise SceneError(f"{where}.force_n: force-controlled steps need model = \"kelvin-voigt\"")
            tap = raw.kind == "tap"
            steps.append(Step(
                kind=raw.kind, at=np.array(raw.at), to=None if raw.to is None else np.array(raw.to),
                start_s=raw.start_s, depth_mm=raw.depth_mm, radius_mm=raw.radius_mm,
                duration_s=(0.15 if tap else 1.0) if raw.duration_s is None else raw.duration_s,
                ramp_s=(0.03 if tap else 0.1) if raw.ramp_s is None else raw.ramp_s,
                approach_mm=raw.approach_mm, shear_mm=raw.shear_mm, force_n=raw.force_n,
                indenter=raw.indenter))
        return cls(
            name=Path(source).stem if head.name is None else head.name,
            steps=tuple(steps),
            loop=head.loop,
            material=head.material,
            model=head.model,
            thickness_mm=head.thickness_mm,
            refine=head.refine,
            skin=dict(head.skin),
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


def _on_surface(mesh: SkinMesh, point: np.ndarray) -> np.ndarray:
    """Project a point onto the tangent plane of its nearest node: smooth paths, on the skin."""
    k = nearest_node(mesh, point)
    n = mesh.normals[k]
    on_plane: np.ndarray = point - ((point - mesh.nodes[k]) @ n) * n
    return on_plane
