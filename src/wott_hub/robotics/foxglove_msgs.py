"""Foxglove's well-known schemas for a Thing's skin, contacts, actions, images and frames.

Messages are ``foxglove-sdk``'s own classes, encoded to protobuf by the SDK (its schemas are
Foxglove's published ``.proto`` files, carried in each channel's schema): the MCAP export and
the live endpoint send these bytes, so Foxglove's 3D, Log and Image panels read them with no
conversion. Units: metres, seconds, newtons; every Thing's vectors in its frame (``frame_id`` =
the Thing id, placed by ``foxglove.FrameTransforms`` on ``/tf``).

- skin: ``SceneUpdate``, entity ``skin``: the rest mesh as one ``TriangleListPrimitive``;
- deformation: ``SceneUpdate``, entity ``deformation``: the triangles touching deformed nodes,
  coloured per vertex by intensity (blue 0 -> red at ``color_max_mm``);
- contacts: ``SceneUpdate``, entity ``contacts``: one ``ArrowPrimitive`` per contact, pointing
  along the force and ending at the contact point, ``FORCE_M_PER_N`` long per newton;
- displacement: ``PointCloud`` of the displaced nodes (x, y, z where they are now; dx, dy, dz;
  node_id);
- actions: ``Log`` (name = the Thing id);
- images: ``CompressedImage`` (PNG, JPEG) or ``RawImage`` (mono8, rgb8, rgba8); a taxel grid as a
  ``RawImage`` of ``32FC1`` pressures;
- frames: ``FrameTransforms`` from ``names.ROOT_FRAME`` to each Thing's frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from foxglove import messages as fm

from .channel import Channel, Out
from .names import ROOT_FRAME, TF_TOPIC, raw_topic

if TYPE_CHECKING:
    from .geometry import FramePose, SkinGeometry
    from .payloads import Contacts, SkinPacket
    from .raw_signals import Displacement, ImageFrame, TaxelGrid

__all__ = ["FORCE_M_PER_N", "FoxgloveEncoder", "transforms"]

FORCE_M_PER_N = 0.02
"""Arrow length per newton of contact force (a 0.5 N press: a 10 mm arrow)."""

_SCHEMAS: dict[type, Channel] = {}


def _channel(cls: type, topic: str, thing: str) -> Channel:
    schema = cls.get_schema()  # type: ignore[attr-defined]  # every message class has it
    return Channel(topic, schema.name, "protobuf", schema.encoding, bytes(schema.data),
                   metadata=(("thing", thing),))


def _stamp(t_ns: int) -> fm.Timestamp:
    return fm.Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


_IDENTITY = fm.Pose(position=fm.Vector3(), orientation=fm.Quaternion(w=1.0))
_MESH_COLOR = fm.Color(r=0.6, g=0.6, b=0.65, a=0.35)
_ARROW_COLOR = fm.Color(r=1.0, g=0.55, b=0.0, a=1.0)
_LEVELS = {"debug": fm.LogLevel.Debug, "info": fm.LogLevel.Info, "warning": fm.LogLevel.Warning}


def _rotation_from_x(d: np.ndarray) -> fm.Quaternion:
    """The rotation taking +x onto the unit vector ``d`` (an arrow's identity points along +x)."""
    x, y, z = (float(v) for v in d)
    w = 1.0 + x  # q = (x cross d, 1 + x . d), normalised
    if w < 1e-9:  # d = -x: half a turn about z
        return fm.Quaternion(x=0.0, y=0.0, z=1.0, w=0.0)
    qx, qy, qz = 0.0, -z, y
    n = (w * w + qy * qy + qz * qz) ** 0.5
    return fm.Quaternion(x=qx / n, y=qy / n, z=qz / n, w=w / n)


def transforms(poses: dict[str, FramePose], t_ns: int) -> fm.FrameTransforms:
    return fm.FrameTransforms(transforms=[
        fm.FrameTransform(timestamp=_stamp(t_ns), parent_frame_id=ROOT_FRAME, child_frame_id=thing,
                          translation=fm.Vector3(x=p.translation[0], y=p.translation[1], z=p.translation[2]),
                          rotation=fm.Quaternion(x=p.rotation[0], y=p.rotation[1], z=p.rotation[2],
                                                 w=p.rotation[3]))
        for thing, p in poses.items()])


class FoxgloveEncoder:
    """One Thing's Foxglove channels and messages. ``throttled``: its scenes are drawn at most a
    few times a second (``mapping.Throttle``); a viewer needs no more, and a scene costs ~100x a
    raw record."""

    throttled = True

    def __init__(self, thing: str, geom: SkinGeometry | None, *, color_max_mm: float = 2.0) -> None:
        self.thing = thing
        self.geom = geom
        self._channels: dict[str, Channel | None] = {}
        self.scale = 1.0 / color_max_mm
        if geom is not None:
            self._points = [fm.Point3(x=x, y=y, z=z) for x, y, z in geom.points.tolist()]
            self._colors = [fm.Color(r=v, g=0.25 * (1 - v), b=1 - v, a=1.0)
                            for v in (i / 255 for i in range(256))]
            self._mesh = fm.TriangleListPrimitive(pose=_IDENTITY, points=self._points, color=_MESH_COLOR,
                                                  indices=geom.tris.ravel().tolist())

    # --- channels -------------------------------------------------------------------------

    def channel(self, kind: str, sub: str = "") -> Channel | None:
        """The channel of ``kind`` (``mesh``, ``deformation``, ``contacts``, ``displacement``, ``log``,
        ``image`` of camera ``sub``, ``taxels``); None: not drawn in Foxglove (``wrench``)."""
        key = f"{kind}:{sub}"
        if key not in self._channels:
            self._channels[key] = self._make(kind, sub)
        return self._channels[key]

    def _make(self, kind: str, sub: str) -> Channel | None:
        t = self.thing
        if kind in ("mesh", "deformation", "contacts"):
            topic = {"mesh": "skin", "deformation": "deformation", "contacts": "contacts"}[kind]
            return _channel(fm.SceneUpdate, f"/{t}/scene/{topic}", t)
        if kind == "displacement":
            return _channel(fm.PointCloud, f"/{t}/scene/displacement", t)
        if kind == "log":
            return _channel(fm.Log, f"/{t}/log", t)
        if kind == "image":
            camera, _, form = sub.partition(":")  # form: raw or compressed
            cls = fm.RawImage if form == "raw" else fm.CompressedImage
            return _channel(cls, f"/{t}/camera/{camera}/{form}", t)
        if kind == "taxels":
            return _channel(fm.RawImage, f"/{t}/taxels", t)
        return None

    @staticmethod
    def tf_channel() -> Channel:
        return _channel(fm.FrameTransforms, TF_TOPIC, "")

    @staticmethod
    def raw_channel(thing: str, kind: int, name: str, schema: bytes) -> Channel:
        return Channel(raw_topic(thing, kind, name), f"wott.{thing}.{name}", "json", "jsonschema", schema,
                       metadata=(("thing", thing), ("kind", "property" if kind else "event"), ("name", name)))

    # --- messages -------------------------------------------------------------------------

    def _scene(self, entity: str, t_ns: int, *, triangles: list[fm.TriangleListPrimitive] | None = None,
               arrows: list[fm.ArrowPrimitive] | None = None) -> bytes:
        ent = fm.SceneEntity(timestamp=_stamp(t_ns), frame_id=self.thing, id=entity, frame_locked=True,
                             metadata=[fm.KeyValuePair(key="thing", value=self.thing)], triangles=triangles,
                             arrows=arrows)
        return fm.SceneUpdate(entities=[ent]).encode()

    def mesh(self, t_ns: int) -> list[Out]:
        ch = self.channel("mesh")
        assert ch is not None and self.geom is not None
        return [Out(ch, t_ns, self._scene("skin", t_ns, triangles=[self._mesh]))]

    def deformation(self, packet: SkinPacket, t_ns: int) -> list[Out]:
        geom, ch = self.geom, self.channel("deformation")
        assert ch is not None and geom is not None
        rows = geom.rows_of(packet.ids)
        keep = (rows >= 0) & (packet.intensity_mm > 0)
        rows, inten = rows[keep], packet.intensity_mm[keep]
        tris = geom.triangles_touching(rows)
        prims = []
        if len(tris):
            corners = geom.tris[tris]
            used, local = np.unique(corners, return_inverse=True)
            level = np.zeros(len(geom.points))
            level[rows] = inten
            idx = np.minimum(255, (level[used] * (255 * self.scale) + 0.5).astype(np.int64)).tolist()
            pts, cols = self._points, self._colors
            prims.append(fm.TriangleListPrimitive(
                pose=_IDENTITY, points=[pts[r] for r in used.tolist()], color=fm.Color(r=1.0, a=1.0),
                colors=[cols[i] for i in idx], indices=local.ravel().tolist()))
        return [Out(ch, t_ns, self._scene("deformation", packet.t_ns, triangles=prims))]

    def contacts(self, c: Contacts, t_ns: int) -> list[Out]:
        ch = self.channel("contacts")
        assert ch is not None
        arrows = []
        for loc, force in zip((c.locations_mm / 1000.0).tolist(), c.forces_n.tolist(), strict=True):
            f = np.array(force)
            n = float(np.linalg.norm(f))
            if not n > 0:
                continue
            d = f / n
            length = n * FORCE_M_PER_N
            tail = np.array(loc) - d * length
            arrows.append(fm.ArrowPrimitive(
                pose=fm.Pose(position=fm.Vector3(x=float(tail[0]), y=float(tail[1]), z=float(tail[2])),
                             orientation=_rotation_from_x(d)),
                shaft_length=0.75 * length, shaft_diameter=0.001, head_length=0.25 * length,
                head_diameter=0.0025, color=_ARROW_COLOR))
        return [Out(ch, t_ns, self._scene("contacts", t_ns, arrows=arrows))]

    def wrench(self, c: Contacts, t_ns: int) -> list[Out]:
        return []  # the arrows say it in Foxglove

    def displacement(self, d: Displacement, t_ns: int) -> list[Out]:
        geom, ch = self.geom, self.channel("displacement")
        assert ch is not None and geom is not None
        rows = geom.rows_of(d.ids)
        keep = rows >= 0
        disp = d.displacement_mm[keep] / 1000.0
        cloud = np.zeros(int(keep.sum()), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("dx", "<f4"),
                                                  ("dy", "<f4"), ("dz", "<f4"), ("node_id", "<u4")])
        now = geom.points[rows[keep]] + disp
        for i, k in enumerate("xyz"):
            cloud[k] = now[:, i]
            cloud["d" + k] = disp[:, i]
        cloud["node_id"] = d.ids[keep]
        f32, u32 = fm.PackedElementFieldNumericType.Float32, fm.PackedElementFieldNumericType.Uint32
        fields = [fm.PackedElementField(name=n, offset=4 * i, type=f32) for i, n in enumerate(
            ("x", "y", "z", "dx", "dy", "dz"))] + [fm.PackedElementField(name="node_id", offset=24, type=u32)]
        msg = fm.PointCloud(timestamp=_stamp(d.t_ns), frame_id=self.thing, pose=_IDENTITY, point_stride=28,
                            fields=fields, data=cloud.tobytes())
        return [Out(ch, t_ns, msg.encode())]

    def log(self, level: str, text: str, t_ns: int) -> list[Out]:
        ch = self.channel("log")
        assert ch is not None
        return [Out(ch, t_ns, fm.Log(timestamp=_stamp(t_ns), level=_LEVELS[level], message=text,
                                     name=self.thing).encode())]

    def image(self, img: ImageFrame) -> list[Out]:
        fmt = img.format
        ch = self.channel("image", f"{img.camera}:{'raw' if fmt == 'raw' else 'compressed'}")
        assert ch is not None
        if fmt == "raw":
            h, w, enc, step, data = img.raw()
            msg = fm.RawImage(timestamp=_stamp(img.t_ns), frame_id=self.thing, width=w, height=h,
                              encoding=enc, step=step, data=data).encode()
        else:
            assert isinstance(img.data, bytes)
            msg = fm.CompressedImage(timestamp=_stamp(img.t_ns), frame_id=self.thing, data=img.data,
                                     format=str(fmt)).encode()
        return [Out(ch, img.t_ns, msg)]

    def taxels(self, grid: TaxelGrid) -> list[Out]:
        ch = self.channel("taxels")
        assert ch is not None
        rows, cols = grid.values.shape
        msg = fm.RawImage(timestamp=_stamp(grid.t_ns), frame_id=self.thing, width=cols, height=rows,
                          encoding="32FC1", step=4 * cols, data=grid.values.astype("<f4").tobytes())
        return [Out(ch, grid.t_ns, msg.encode())]
