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
- ``contacts/markers``: ``visualization_msgs/msg/MarkerArray`` (one ``ARROW`` per contact, id =
  its index; ``DELETE`` for the arrows of contacts that ended) and ``contacts/wrench``:
  ``geometry_msgs/msg/WrenchStamped`` (the net force, its torque about the frame's origin), one
  each per ``contactInformation``;
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


@functools.cache
def _fields(names: tuple[str, ...]) -> list[Any]:
    T = _types()
    fields = [T.PointField(name=n, offset=4 * i, datatype=T.PointField.FLOAT32, count=1)
              for i, n in enumerate(names)]
    fields.append(T.PointField(name="node_id", offset=4 * len(names), datatype=T.PointField.UINT32, count=1))
    return fields


def _cloud(t_ns: int, frame: str, names: tuple[str, ...], values: np.ndarray, ids: np.ndarray) -> Any:
    """A PointCloud2 of float32 ``names`` (the columns of ``values``) and a uint32 ``node_id`` per
    point, little-endian, dense."""
    n, k = len(ids), len(names)
    buf = np.empty((n, k + 1), dtype="<f4")
    buf[:, :k] = values
    buf.view("<u4")[:, k] = ids
    step = 4 * (k + 1)
    return _types().PointCloud2(header=_header(t_ns, frame), height=1, width=n, fields=_fields(names),
                                is_bigendian=False, point_step=step, row_step=step * n,
                                data=buf.view(np.uint8).reshape(-1), is_dense=True)


class Ros2Encoder:
    """One Thing's ROS 2 topics and messages (every record, no throttle: a bag is a recording)."""

    throttled = False

    def __init__(self, thing: str, ns: str, geom: SkinGeometry | None) -> None:
        self.thing = thing
        self.ns = ns
        self.geom = geom
        self._channels: dict[str, Channel | None] = {}
        self._arrows = 0  # arrows shown now (contacts/markers): those beyond the next count are deleted
        T = _types()
        self._pose = T.Pose(position=T.Point(x=0.0, y=0.0, z=0.0),
                            orientation=T.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
        self._forever = T.Duration(sec=0, nanosec=0)
        self._mesh_file = T.MeshFile(filename="", data=_EMPTY_U8)
        self._orange = T.ColorRGBA(r=1.0, g=0.55, b=0.0, a=1.0)

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
                color: tuple[float, float, float, float] | None = (0, 0, 0, 0),
                scale: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> Any:
        T = _types()
        header = _header(t_ns, self.thing)
        return T.Marker(
            header=header, ns=ns, id=mid, type=mtype, action=action, pose=self._pose,
            scale=T.Vector3(x=scale[0], y=scale[1], z=scale[2]),
            color=self._orange if color is None else T.ColorRGBA(r=color[0], g=color[1], b=color[2],
                                                                 a=color[3]),
            lifetime=self._forever, frame_locked=True, points=list(points), colors=[],
            texture_resource="", texture=T.CompressedImage(header=header, format="", data=_EMPTY_U8),
            uv_coordinates=[], text="", mesh_resource="", mesh_file=self._mesh_file,
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
        values = np.empty((int(keep.sum()), 4))
        values[:, :3] = geom.points[rows[keep]]
        values[:, 3] = packet.intensity_mm[keep] / 1000.0
        msg = _cloud(packet.t_ns, self.thing, ("x", "y", "z", "intensity"), values, packet.ids[keep])
        return [Out(ch, t_ns, msg)]

    def displacement(self, d: Displacement, t_ns: int) -> list[Out]:
        geom, ch = self.geom, self.channel("displacement")
        assert geom is not None and ch is not None
        rows = geom.rows_of(d.ids)
        keep = rows >= 0
        disp = d.displacement_mm[keep] / 1000.0
        now = geom.points[rows[keep]] + disp
        msg = _cloud(d.t_ns, self.thing, ("x", "y", "z", "dx", "dy", "dz"), np.hstack([now, disp]),
                     d.ids[keep])
        return [Out(ch, t_ns, msg)]

    def contacts(self, c: Contacts, t_ns: int) -> list[Out]:
        """One ``ARROW`` per contact (id = its index), ending at the contact point along the force;
        the arrows of contacts that ended (ids from the new count up) ``DELETE``d."""
        T, ch = _types(), self.channel("contacts")
        assert ch is not None
        k = FORCE_M_PER_N
        markers = []
        pairs = zip((c.locations_mm / 1000.0).tolist(), c.forces_n.tolist(), strict=True)
        for i, ((x, y, z), (fx, fy, fz)) in enumerate(pairs):
            head = 0.25 * k * (fx * fx + fy * fy + fz * fz) ** 0.5
            markers.append(self._marker(
                t_ns, "contacts", i, T.Marker.ARROW, T.Marker.ADD, color=None, scale=(0.001, 0.0025, head),
                points=[T.Point(x=x - fx * k, y=y - fy * k, z=z - fz * k), T.Point(x=x, y=y, z=z)]))
        n = len(markers)
        markers += [self._marker(t_ns, "contacts", i, T.Marker.ARROW, T.Marker.DELETE)
                    for i in range(n, self._arrows)]
        self._arrows = n
        return [Out(ch, t_ns, T.MarkerArray(markers=markers))]

    def wrench(self, c: Contacts, t_ns: int) -> list[Out]:
        """The net force on the skin and its torque about the frame's origin (sum of r x F)."""
        T, ch = _types(), self.channel("wrench")
        assert ch is not None
        f, tq = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        pairs = zip((c.locations_mm / 1000.0).tolist(), c.forces_n.tolist(), strict=True)
        for (x, y, z), (fx, fy, fz) in pairs:
            f[0] += fx
            f[1] += fy
            f[2] += fz
            tq[0] += y * fz - z * fy
            tq[1] += z * fx - x * fz
            tq[2] += x * fy - y * fx
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
