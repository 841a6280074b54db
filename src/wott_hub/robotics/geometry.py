"""A Thing's skin as the robotics tools draw it: nodes in metres, triangles, the sensor frame.

Read from the values a Tactile TD serves (``skinNodes``, ``skinCells``,
``sensorCoordinateFrame``; docs/tactile-td.md), in the hub's process or from history's record of
them. Lengths leave in metres (ROS REP 103, Foxglove): the TD's millimetres / 1000. Every vector
the Thing reports is in its ``sensorCoordinateFrame``; that frame's own placement, the origin and
the axes the TD gives, is published as the transform from ``names.ROOT_FRAME`` to the frame
(a rotation whose columns are the axes, made orthonormal; identity when the TD gives none).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wott_hub.errors import InvalidInput

__all__ = ["FramePose", "SkinGeometry", "frame_pose"]


@dataclass(frozen=True)
class FramePose:
    """Where a Thing's frame sits under the root frame: translation (m) and rotation (x, y, z, w)."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


def _vec(v: Any, default: tuple[float, float, float]) -> np.ndarray:
    if not isinstance(v, dict):
        return np.array(default, dtype=np.float64)
    return np.array([float(v.get(k, d)) for k, d in zip("xyz", default, strict=True)], dtype=np.float64)


def _quaternion(r: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method: stable everywhere)."""
    t = float(np.trace(r))
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        w, x, y, z = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = np.empty(3)
        q[i] = 0.25 * s
        q[j] = (r[j, i] + r[i, j]) / s
        q[k] = (r[k, i] + r[i, k]) / s
        w = (r[k, j] - r[j, k]) / s
        x, y, z = q
    n = np.sqrt(w * w + x * x + y * y + z * z)
    return (float(x / n), float(y / n), float(z / n), float(w / n))


def frame_pose(frame: Any) -> FramePose:
    """The pose of a ``sensorCoordinateFrame`` value (None or absent: identity).

    ``InvalidInput`` for axes that span no right-handed frame (parallel, zero, or NaN)."""
    if not isinstance(frame, dict):
        return FramePose()
    origin = _vec(frame.get("originLocation"), (0.0, 0.0, 0.0)) / 1000.0
    axes = frame.get("axisOrientation")
    if not isinstance(axes, dict):
        axes = {}
    x = _vec(axes.get("xAxis"), (1.0, 0.0, 0.0))
    y = _vec(axes.get("yAxis"), (0.0, 1.0, 0.0))
    if not (np.isfinite(origin).all() and np.isfinite(x).all() and np.isfinite(y).all()):
        raise InvalidInput("sensorCoordinateFrame: not a finite origin and axes")
    nx = np.linalg.norm(x)
    y = y - x * (x @ y) / (nx * nx) if nx > 0 else y  # Gram-Schmidt: y made normal to x
    ny = np.linalg.norm(y)
    if nx < 1e-12 or ny < 1e-12:
        raise InvalidInput("sensorCoordinateFrame: xAxis and yAxis do not span a plane")
    ex, ey = x / nx, y / ny
    rot = np.column_stack([ex, ey, np.cross(ex, ey)])  # right-handed by construction
    return FramePose(tuple(float(v) for v in origin), _quaternion(rot))  # type: ignore[arg-type]


class SkinGeometry:
    """The rest mesh of one Thing: ``points`` (N x 3, m) in node order, ``rows`` of node ids,
    ``tris`` (T x 3 rows; quads split into two triangles), and for each row the triangles using it."""

    def __init__(self, thing: str, static: dict[str, Any]) -> None:
        try:
            nodes = static["skinNodes"]["arrayOfNodes"]
            ids = np.array([int(n["nodeID"]) for n in nodes], dtype=np.int64)
            mm = np.array([(n["nodeLocation"]["x"], n["nodeLocation"]["y"], n["nodeLocation"]["z"])
                           for n in nodes], dtype=np.float64).reshape(-1, 3)
        except (KeyError, TypeError, ValueError) as e:
            raise InvalidInput(f"{thing}: skinNodes is not a list of nodes with nodeID and nodeLocation "
                               f"({e})") from None
        self.thing = thing
        self.frame_id = thing
        self.ids = ids
        self.points = mm / 1000.0
        top = int(ids.max()) + 1 if len(ids) else 0
        self._lut = np.full(top + 1, -1, dtype=np.int64)  # node id -> row (-1: no such node)
        if len(ids) and ids.min() < 0:
            raise InvalidInput(f"{thing}: skinNodes has a negative nodeID")
        self._lut[ids] = np.arange(len(ids))
        tris: list[tuple[int, int, int]] = []
        for cell in (static.get("skinCells") or {}).get("arrayOfCells") or []:
            corners = self.rows_of(np.array(cell.get("connectedNodes") or [], dtype=np.int64)).tolist()
            rows = [r for r in corners if r >= 0]
            tris.extend((rows[0], rows[k], rows[k + 1]) for k in range(1, len(rows) - 1))  # a fan
        self.tris = np.array(tris, dtype=np.int64).reshape(-1, 3)
        of_row: list[list[int]] = [[] for _ in range(len(ids))]
        for t, tri in enumerate(self.tris.tolist()):
            for r in tri:
                of_row[r].append(t)
        self.of_row = of_row
        self.pose = frame_pose(static.get("sensorCoordinateFrame"))

    @classmethod
    def of(cls, thing: str, static: dict[str, Any] | None) -> SkinGeometry | None:
        """The skin of a Thing whose values hold ``skinNodes``; None for any other Thing."""
        if not static or not isinstance(static.get("skinNodes"), dict):
            return None
        return cls(thing, static)

    def rows_of(self, ids: np.ndarray) -> np.ndarray:
        """The row of each node id (-1 for an id the mesh does not have)."""
        ids = np.asarray(ids, dtype=np.int64)
        out = np.full(len(ids), -1, dtype=np.int64)
        ok = (ids >= 0) & (ids < len(self._lut))
        out[ok] = self._lut[ids[ok]]
        return out

    def triangles_touching(self, rows: np.ndarray) -> np.ndarray:
        """The triangles with a corner in ``rows``, ascending."""
        found = {t for r in rows.tolist() for t in self.of_row[r]}
        return np.array(sorted(found), dtype=np.int64)
