"""ROS 2 messages for a Thing's skin, contacts, actions, images and frames (ROS 2 Jazzy types).

Message classes, their definitions (``ros2msg``, embedded in the bag's schemas) and CDR come
from ``rosbags``' type store for Jazzy (the current LTS; Humble's ``Marker`` lacks the texture and
mesh-file fields Jazzy added, docs/robotics.md), plus ``tactile_msgs/msg/TactileState`` from
tactile_toolbox. Never hand-written CDR. Units SI (REP 103): metres, newtons, newton-metres;
every vector in the Thing's frame (``header.frame_id`` = the Thing id).

Topics under the Thing's namespace ``/<ns>`` (``names.ros_namespaces``):

- ``skin/mesh``: ``visualization_msgs/msg/MarkerArray`` (one ``TRIANGLE_LIST``), latched; at the
  start, then every minute;
- ``skin/deformation``: ``sensor_msgs/msg/PointCloud2`` (x, y, z at rest; intensity, m; node_id),
  one per ``skinDeformedDetection``;
- ``skin/displacement``: ``sensor_msgs/msg/PointCloud2`` (x, y, z now; dx, dy, dz; node_id), one per
  ``skinDisplacement``;
- ``contacts/markers``: ``visualization_msgs/msg/MarkerArray`` (``DELETEALL``, then one ``ARROW``
  per contact) and ``contacts/wrench``: ``geometry_msgs/msg/WrenchStamped`` (the net force, its
  torque about the frame's origin), one each per ``contactInformation``;
- ``actions``: ``rcl_interfaces/msg/Log`` (name = the Thing id), per ``actionDetection``,
  ``actionDetails``, ``deviceAction``;
- ``camera/<name>/image_raw`` (``sensor_msgs/msg/Image``) or ``.../image_raw/compressed``
  (``CompressedImage``); ``taxels``: ``tactile_msgs/msg/TactileState`` (one sensor, row-major);
- ``events/<name>``, ``properties/<name>``: ``std_msgs/msg/String`` (the JSON) for any other record.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .channel import Channel, Out
from .names import ROOT_FRAME, TF_STATIC_TOPIC

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from .geometry import FramePose, SkinGeometry
    from .payloads import Contacts, SkinPacket
    from .raw_signals import Displacement, ImageFrame, TaxelGrid

__all__ = ["TACTILE_STATE", "Ros2Encoder", "ros_string", "tf_static", "typestore"]

TACTILE_STATE = ("tactile_msgs/msg/TactileState",
                 "std_msgs/Header header\nsensor_msgs/ChannelFloat32[] sensors\n")
"""tactile_toolbox's TactileState (github.com/ubi-agni/tactile_toolbox, tactile_msgs/msg)."""

FORCE_M_PER_N = 0.02  # as foxglove_msgs: the same arrows in RViz and Foxglove
_LOG = {"debug": 10, "info": 20, "warning": 30}


@functools.cache
def typestore() -> Typestore:
    """ROS 2 Jazzy's message types and tactile_msgs' TactileState."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(TACTILE_STATE[1], TACTILE_STATE[0]))
    return ts


class _T:
    """The message classes, looked up once."""

    def __init__(self) -> None:
        t: dict[str, Any] = dict(typestore().types)  # generated classes: typed Any here
        self.Time, self.Duration = t["builtin_interfaces/msg/Time"], t["builtin_interfaces/msg/Duration"]
        self.Header, self.String = t["std_msgs/msg/Header"], t["std_msgs/msg/String"]
        self.ColorRGBA = t["std_msgs/msg/ColorRGBA"]
        self.Point, self.Vector3 = t["geometry_msgs/msg/Point"], t["geometry_msgs/msg/Vector3"]
        self.Quaternion, self.Pose = t["geometry_msgs/msg/Quaternion"], t["geometry_msgs/msg/Pose"]
        self.Wrench, self.WrenchStamped = t["geometry_msgs/msg/Wrench"], t["geometry_msgs/msg/WrenchStamped"]
        self.Transform = t["geometry_msgs/msg/Transform"]
        self.TransformStamped = t["geometry_msgs/msg/TransformStamped"]
        self.TFMessage = t["tf2_msgs/msg/TFMessage"]
        self.Marker = t["visualization_msgs/msg/Marker"]
        self.MarkerArray = t["visualization_msgs/msg/MarkerArray"]
        self.MeshFile = t["visualization_msgs/msg/MeshFile"]
        self.PointCloud2, self.PointField = t["sensor_msgs/msg/PointCloud2"], t["sensor_msgs/msg/PointField"]
        self.Image, self.CompressedImage = t["sensor_msgs/msg/Image"], t["sensor_msgs/msg/CompressedImage"]
        self.ChannelFloat32 = t["sensor_msgs/msg/ChannelFloat32"]
        self.TactileState = t[TACTILE_STATE[0]]
        self.Log = t["rcl_interfaces/msg/Log"]


@functools.cache
def _types() -> _T:
    return _T()


_EMPTY_U8 = np.zeros(0, dtype=np.uint8)


def _header(t_ns: int, frame: str) -> Any:
    T = _types()
    return T.Header(stamp=T.Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000), frame_id=frame)


def _channel(topic: str, msgtype: str, latched: bool = False) -> Channel:
    return Channel(topic, msgtype, "cdr", "ros2msg", latched=latched)


def ros_string(text: str) -> Any:
    """A ``std_msgs/msg/String``: a record no typed message carries, as its JSON text."""
    return _types().String(data=text)


def tf_static(poses: dict[str, FramePose], t_ns: int) -> Out:
    T = _types()
    tfs = [T.TransformStamped(
        header=_header(t_ns, ROOT_FRAME), child_frame_id=thing,
        transform=T.Transform(
            translation=T.Vector3(x=p.translation[0], y=p.translation[1], z=p.translation[2]),
            rotation=T.Quaternion(x=p.rotation[0], y=p.rotation[1], z=p.rotation[2], w=p.rotation[3])))
        for thing, p in poses.items()]
    ch = _channel(TF_STATIC_TOPIC, "tf2_msgs/msg/TFMessage", latched=True)
    return Out(ch, t_ns, T.TFMessage(transforms=tfs))


def _cloud(t_ns: int, frame: str, names: tuple[str, ...], columns: list[np.ndarray], ids: np.ndarray) -> Any:
    """A PointCloud2 of float32 ``names`` and a uint32 ``node_id`` per point, little-endian, dense."""
    T = _types()
    dtype = [(n, "<f4") for n in names] + [("node_id", "<u4")]
    data = np.zeros(len(ids), dtype=dtype)
    for n, col in zip(names, columns, strict=True):
        data[n] = col
    data["node_id"] = ids
    fields = [T.PointField(name=n, offset=4 * i, datatype=T.PointField.FLOAT32, count=1)
              for i, n in enumerate(names)]
    fields.append(T.PointField(name="node_id", offset=4 * len(names), datatype=T.PointField.UINT32, count=1))
    step = 4 * (len(names) + 1)
    return T.PointCloud2(header=_header(t_ns, frame), height=1, width=len(ids), fields=fields,
                         is_bigendian=False, point_step=step, row_step=step * len(ids),
                         data=data.view(np.uint8).reshape(-1), is_dense=True)


class Ros2Encoder:
    """One Thing's ROS 2 topics and messages (every record, no throttle: a bag is a recording)."""

    throttled = False

    def __init__(self, thing: str, ns: str, geom: SkinGeometry | None) -> None:
        self.thing = thing
        self.ns = ns
        self.geom = geom
        self._channels: dict[str, Channel | None] = {}

    def channel(self, kind: str, sub: str = "") -> Channel | None:
        key = f"{kind}:{sub}"
        if key not in self._channels:
            self._channels[key] = self._make(kind, sub)
        return self._channels[key]

    def _make(self, kind: str, sub: str) -> Channel | None:
        ns = f"/{self.ns}"
        simple = {"mesh": ("skin/mesh", "visualization_msgs/msg/MarkerArray"),
                  "deformation": ("skin/deformation", "sensor_msgs/msg/PointCloud2"),
                  "displacement": ("skin/displacement", "sensor_msgs/msg/PointCloud2"),
                  "contacts": ("contacts/markers", "visualization_msgs/msg/MarkerArray"),
                  "wrench": ("contacts/wrench", "geometry_msgs/msg/WrenchStamped"),
                  "log": ("actions", "rcl_interfaces/msg/Log"),
                  "taxels": ("taxels", TACTILE_STATE[0])}
        if kind in simple:
            topic, msgtype = simple[kind]
            return _channel(f"{ns}/{topic}", msgtype, latched=kind == "mesh")
        if kind == "image":
            camera, _, form = sub.partition(":")
            if form == "raw":
                return _channel(f"{ns}/camera/{camera}/image_raw", "sensor_msgs/msg/Image")
            return _channel(f"{ns}/camera/{camera}/image_raw/compressed", "sensor_msgs/msg/CompressedImage")
        if kind == "string":
            return _channel(f"{ns}/{sub}", "std_msgs/msg/String")
        return None

    # --- messages ---------------------------------------------------------------------------

    def _marker(self, t_ns: int, ns: str, mid: int, mtype: int, action: int, *, points: Sequence[Any] = (),
                color: tuple[float, float, float, float] = (0, 0, 0, 0),
                scale: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Any:
        T = _types()
        header = _header(t_ns, self.thing)
        return T.Marker(
            header=header, ns=ns, id=mid, type=mtype, action=action,
            pose=T.Pose(position=T.Point(x=0.0, y=0.0, z=0.0),
                        orientation=T.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            scale=T.Vector3(x=scale[0], y=scale[1], z=scale[2]),
            color=T.ColorRGBA(r=color[0], g=color[1], b=color[2], a=color[3]),
            lifetime=T.Duration(sec=0, nanosec=0), frame_locked=True, points=list(points), colors=[],
            texture_resource="", texture=T.CompressedImage(header=header, format="", data=_EMPTY_U8),
            uv_coordinates=[], text="", mesh_resource="", mesh_file=T.MeshFile(filename="", data=_EMPTY_U8),
            mesh_use_embedded_materials=False)

    def mesh(self, t_ns: int) -> list[Out]:
        T, geom, ch = _types(), self.geom, self.channel("mesh")
        assert geom is not None and ch is not None
        pts = [T.Point(x=x, y=y, z=z) for x, y, z in geom.points[geom.tris.ravel()].tolist()]
        m = self._marker(t_ns, "skin", 0, T.Marker.TRIANGLE_LIST, T.Marker.ADD, points=pts,
                         color=(0.6, 0.6, 0.65, 0.35))
        return [Out(ch, t_ns, T.MarkerArray(markers=[m]))]

    def deformation(self, packet: SkinPacket, t_ns: int) -> list[Out]:
        geom, ch = self.geom, self.channel("deformation")
        assert geom is not None and ch is not None
        rows = geom.rows_of(packet.ids)
        keep = rows >= 0
        at = geom.points[rows[keep]]
        msg = _cloud(packet.t_ns, self.thing, ("x", "y", "z", "intensity"),
                     [at[:, 0], at[:, 1], at[:, 2], packet.intensity_mm[keep] / 1000.0], packet.ids[keep])
        return [Out(ch, t_ns, msg)]

    def displacement(self, d: Displacement, t_ns: int) -> list[Out]:
        geom, ch = self.geom, self.channel("displacement")
        assert geom is not None and ch is not None
        rows = geom.rows_of(d.ids)
        keep = rows >= 0
        disp = d.displacement_mm[keep] / 1000.0
        now = geom.points[rows[keep]] + disp
        msg = _cloud(d.t_ns, self.thing, ("x", "y", "z", "dx", "dy", "dz"),
                     [now[:, 0], now[:, 1], now[:, 2], disp[:, 0], disp[:, 1], disp[:, 2]], d.ids[keep])
        return [Out(ch, t_ns, msg)]

    def contacts(self, c: Contacts, t_ns: int) -> list[Out]:
        T, ch = _types(), self.channel("contacts")
        assert ch is not None
        markers = [self._marker(t_ns, "contacts", 0, T.Marker.ARROW, T.Marker.DELETEALL)]
        loc_m = c.locations_mm / 1000.0
        for i, (loc, f) in enumerate(zip(loc_m.tolist(), c.forces_n.tolist(), strict=True)):
            tail = np.array(loc) - np.array(f) * FORCE_M_PER_N
            markers.append(self._marker(
                t_ns, "contacts", i, T.Marker.ARROW, T.Marker.ADD, color=(1.0, 0.55, 0.0, 1.0),
                scale=(0.001, 0.0025, 0.25 * float(np.linalg.norm(f)) * FORCE_M_PER_N),
                points=[T.Point(x=float(tail[0]), y=float(tail[1]), z=float(tail[2])),
                        T.Point(x=loc[0], y=loc[1], z=loc[2])]))
        return [Out(ch, t_ns, T.MarkerArray(markers=markers))]

    def wrench(self, c: Contacts, t_ns: int) -> list[Out]:
        """The net force on the skin and its torque about the frame's origin (sum of r x F)."""
        T, ch = _types(), self.channel("wrench")
        assert ch is not None
        force = c.forces_n.sum(axis=0) if len(c.forces_n) else np.zeros(3)
        torque = np.cross(c.locations_mm / 1000.0, c.forces_n).sum(axis=0) if len(c.forces_n) else np.zeros(3)
        f, tq = force.tolist(), torque.tolist()
        msg = T.WrenchStamped(header=_header(t_ns, self.thing), wrench=T.Wrench(
            force=T.Vector3(x=f[0], y=f[1], z=f[2]), torque=T.Vector3(x=tq[0], y=tq[1], z=tq[2])))
        return [Out(ch, t_ns, msg)]

    def log(self, level: str, text: str, t_ns: int) -> list[Out]:
        T, ch = _types(), self.channel("log")
        assert ch is not None
        msg = T.Log(stamp=T.Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000), level=_LOG[level],
                    name=self.thing, msg=text, file="", function="", line=0)
        return [Out(ch, t_ns, msg)]

    def string(self, path: str, text: str, t_ns: int) -> list[Out]:
        ch = self.channel("string", path)
        assert ch is not None
        return [Out(ch, t_ns, _types().String(data=text))]

    def image(self, img: ImageFrame) -> list[Out]:
        T = _types()
        fmt = img.format
        ch = self.channel("image", f"{img.camera}:{'raw' if fmt == 'raw' else 'compressed'}")
        assert ch is not None
        header = _header(img.t_ns, self.thing)
        if fmt == "raw":
            h, w, enc, step, data = img.raw()
            msg = T.Image(header=header, height=h, width=w, encoding=enc, is_bigendian=0, step=step,
                          data=np.frombuffer(data, dtype=np.uint8))
        else:
            assert isinstance(img.data, bytes)
            msg = T.CompressedImage(header=header, format=str(fmt),
                                    data=np.frombuffer(img.data, dtype=np.uint8))
        return [Out(ch, img.t_ns, msg)]

    def taxels(self, grid: TaxelGrid) -> list[Out]:
        T, ch = _types(), self.channel("taxels")
        assert ch is not None
        msg = T.TactileState(header=_header(grid.t_ns, self.thing), sensors=[T.ChannelFloat32(
            name=self.thing, values=grid.values.astype(np.float32).ravel())])
        return [Out(ch, grid.t_ns, msg)]
