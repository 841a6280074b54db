"""The one mapping: what each record of a Thing becomes in Foxglove and in ROS 2.

Used by the MCAP export (``history/mcap.py``, profile ``foxglove``), the live Foxglove endpoint
(``live.py``, ``foxglove``: the same channels, schemas and bytes as the MCAP file) and the rosbag2
export (``history/rosbag2.py``, profile ``ros2``). Per record:

- any record: Foxglove: its raw channel ``/<thing>/events|properties/<name>`` (JSON, the TD's
  schema); ROS 2: ``std_msgs/String``, only when nothing below maps it;
- ``skinDeformedDetection``: the deformation scene (throttled) | ``skin/deformation`` PointCloud2;
- ``skinDisplacement`` (issue 29): a point cloud (throttled) | ``skin/displacement`` PointCloud2;
- ``contactInformation``: the contact arrows scene (throttled) | ``contacts/markers`` MarkerArray
  and ``contacts/wrench`` WrenchStamped;
- ``actionDetection``, ``actionDetails``, ``deviceAction``: ``Log`` | ``actions`` (rcl_interfaces Log);
- a Thing with a skin, at its first record then every ``MESH_EVERY_S``: the mesh scene |
  ``skin/mesh`` MarkerArray;
- images and taxel grids (issue 29; not records: ``image``, ``taxels``): CompressedImage or
  RawImage | Image, CompressedImage, TactileState;
- the fleet (``transforms``): ``/tf`` FrameTransforms | ``/tf_static`` TFMessage.

Scenes are throttled, never stale (``Throttle``): at most ``scene_hz`` a second per channel; a
packet arriving before its channel's next slot is kept, replaced by any later one, and drawn when
the slot comes (``due``), so the last state is always drawn. A bag is a recording: every record,
no throttle. A payload of a shape the mapping cannot read (a foreign driver's) stays on its raw
channel (counted in ``unreadable``), never an error.

``wanted`` (the live endpoint): a predicate on a channel's topic; what no client subscribes to is
not built at all.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from wott_hub.errors import InvalidInput
from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record
from wott_hub.td.actions import DEVICE_ACTION_EVENT

from .channel import Channel, Out
from .geometry import FramePose, SkinGeometry
from .names import raw_topic, unique_token
from .payloads import Contacts, SkinPacket, action_text, contacts, skin_packet
from .raw_signals import DISPLACEMENT_EVENT, Displacement, ImageFrame, TaxelGrid, displacement

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["CONTACTS", "LOG_EVENTS", "MESH_EVERY_S", "PROFILES", "SKIN_EVENT", "Encoder", "FleetMapping",
           "ThingMapping", "Throttle", "schema_of"]

MESH_EVERY_S = 60.0
"""The rest mesh again this often: a viewer seeking into a recording finds it."""
SKIN_EVENT = "skinDeformedDetection"
CONTACTS = "contactInformation"
LOG_EVENTS = {"actionDetection": "info", "actionDetails": "debug", **{n: "info" for n in DEVICE_ACTION_EVENT}}
"""Events shown as log lines, and their level."""
PROFILES = ("foxglove", "ros2")

Wanted = Callable[[str], bool]


def _all(topic: str) -> bool:
    return True


class Encoder(Protocol):
    """One Thing's messages in one encoding (``foxglove_msgs.FoxgloveEncoder``,
    ``ros2_msgs.Ros2Encoder``). ``channel`` is None for what the encoding does not carry."""

    throttled: bool
    geom: SkinGeometry | None

    def channel(self, kind: str, sub: str = "") -> Channel | None: ...
    def mesh(self, t_ns: int) -> list[Out]: ...
    def deformation(self, packet: SkinPacket, t_ns: int) -> list[Out]: ...
    def displacement(self, d: Displacement, t_ns: int) -> list[Out]: ...
    def contacts(self, c: Contacts, t_ns: int) -> list[Out]: ...
    def wrench(self, c: Contacts, t_ns: int) -> list[Out]: ...
    def log(self, level: str, text: str, t_ns: int) -> list[Out]: ...
    def image(self, img: ImageFrame) -> list[Out]: ...
    def taxels(self, grid: TaxelGrid) -> list[Out]: ...


def schema_of(td: dict[str, Any] | None, kind: int, name: str) -> dict[str, Any]:
    """An affordance's data schema from its Thing's TD (forms and TD-only terms left out)."""
    aff = ((td or {}).get("events" if kind == KIND_EVENT else "properties") or {}).get(name) or {}
    schema = aff.get("data", {}) if kind == KIND_EVENT else aff
    out = {k: v for k, v in schema.items() if k not in ("forms", "observable", "uriVariables", "@type")}
    out.setdefault("type", "object")
    out["title"] = name
    return out


class Throttle:
    """At most one drawing per ``1/hz`` s (10 % slack: 120 Hz drawn at 30 Hz is every 4th), the
    latest undrawn state kept until its slot."""

    __slots__ = ("next", "pending", "period", "slack")

    def __init__(self, hz: float) -> None:
        self.period = int(1e9 / hz)
        self.slack = self.period // 10
        self.next = -(2**62)
        self.pending: tuple[int, Callable[[int], list[Out]]] | None = None

    def offer(self, t_ns: int, draw: Callable[[int], list[Out]]) -> list[Out]:
        """Draw now (the slot has come) or keep ``draw`` as the latest pending state."""
        if t_ns + self.slack >= self.next:
            self.pending = None
            self.next = t_ns + self.period
            return draw(t_ns)
        self.pending = (t_ns, draw)
        return []

    def due(self, now_ns: int) -> list[Out]:
        """The pending state, drawn if its slot has come by ``now_ns`` (logged at the slot's time)."""
        if self.pending is None or now_ns + self.slack < self.next:
            return []
        _, draw = self.pending
        at = max(self.next, self.pending[0])
        self.pending = None
        self.next = at + self.period
        return draw(at)

    @property
    def deadline(self) -> int | None:
        return None if self.pending is None else self.next


class ThingMapping:
    """One Thing: its encoder, its throttles, when its mesh is due."""

    def __init__(self, thing: str, encoder: Encoder, *, scene_hz: float = 30.0) -> None:
        self.thing = thing
        self.enc = encoder
        self.geom = encoder.geom
        self.scene_hz = scene_hz
        self.throttles: dict[str, Throttle] = {}
        self.next_mesh = -(2**62)
        self.unreadable = 0

    def _scene(self, kind: str, t_ns: int, draw: Callable[[int], list[Out]]) -> list[Out]:
        if not self.enc.throttled:
            return draw(t_ns)
        th = self.throttles.get(kind)
        if th is None:
            th = self.throttles[kind] = Throttle(self.scene_hz)
        return th.offer(t_ns, draw)

    def _wants(self, kind: str, wanted: Wanted) -> bool:
        ch = self.enc.channel(kind)
        return ch is not None and wanted(ch.topic)

    def mesh(self, t_ns: int) -> list[Out]:
        """The rest mesh now (a Thing without a skin: nothing)."""
        if self.geom is None:
            return []
        self.next_mesh = t_ns + int(MESH_EVERY_S * 1e9)
        return self.enc.mesh(t_ns)

    def record(self, rec: Record, wanted: Wanted = _all) -> list[Out]:
        """What ``rec`` becomes (its raw form is ``raw``'s: the caller asks for both)."""
        out: list[Out] = []
        t, name, enc = rec.t_ns, rec.name, self.enc
        if self.geom is not None and t >= self.next_mesh and self._wants("mesh", wanted):
            out += self.mesh(t)
        try:
            if rec.kind == KIND_EVENT and name == SKIN_EVENT and self.geom is not None:
                if self._wants("deformation", wanted):
                    data = rec.data
                    out += self._scene("deformation", t, lambda at: enc.deformation(skin_packet(data, t), at))
            elif rec.kind == KIND_PROPERTY and name == CONTACTS:
                if self._wants("contacts", wanted) or self._wants("wrench", wanted):
                    c = contacts(rec.data)
                    if self._wants("contacts", wanted):
                        out += self._scene("contacts", t, lambda at: enc.contacts(c, at))
                    if self._wants("wrench", wanted):
                        out += enc.wrench(c, t)
            elif rec.kind == KIND_EVENT and name == DISPLACEMENT_EVENT and self.geom is not None:
                if self._wants("displacement", wanted):
                    data = rec.data
                    out += self._scene("displacement", t,
                                       lambda at: enc.displacement(displacement(data, t), at))
            elif rec.kind == KIND_EVENT and name in LOG_EVENTS:
                if self._wants("log", wanted):
                    out += enc.log(LOG_EVENTS[name], action_text(name, rec.data), t)
            else:
                return out
        except InvalidInput:
            self.unreadable += 1
            return out
        return out

    def mapped(self, rec: Record) -> bool:
        """Whether ``record`` turns ``rec`` into a typed message (else only its raw form carries it)."""
        name = rec.name
        if rec.kind == KIND_PROPERTY:
            return name == CONTACTS
        return name in LOG_EVENTS or (self.geom is not None and name in (SKIN_EVENT, DISPLACEMENT_EVENT))

    def due(self, now_ns: int) -> list[Out]:
        out: list[Out] = []
        for th in self.throttles.values():
            if th.pending is not None:
                out += th.due(now_ns)
        return out

    def image(self, img: ImageFrame) -> list[Out]:
        return self.enc.image(img)

    def taxels(self, grid: TaxelGrid) -> list[Out]:
        return self.enc.taxels(grid)


class FleetMapping:
    """The mapping of every Thing of an export or of the live endpoint, in one ``profile``
    (``foxglove`` or ``ros2``)."""

    def __init__(self, profile: str, *, scene_hz: float = 30.0, color_max_mm: float = 2.0) -> None:
        if profile not in PROFILES:
            raise ValueError(f"profile must be one of {PROFILES}, got {profile!r}")
        self.profile = profile
        self.scene_hz = scene_hz
        self.color_max_mm = color_max_mm
        self.things: dict[str, ThingMapping] = {}
        self.tds: dict[str, dict[str, Any]] = {}
        self._raw: dict[tuple[str, int, str], Channel] = {}
        self._ns: dict[str, str] = {}

    def add(self, thing: str, td: dict[str, Any] | None, static: dict[str, Any] | None) -> ThingMapping:
        """Map ``thing`` from now on (its TD for the raw channels' schemas, its static property
        values for the skin). A skin the mapping cannot read: the Thing is mapped without one."""
        try:
            geom = SkinGeometry.of(thing, static)
        except InvalidInput:
            geom = None
        if self.profile == "foxglove":
            from .foxglove_msgs import FoxgloveEncoder

            enc: Encoder = FoxgloveEncoder(thing, geom, color_max_mm=self.color_max_mm)
        else:
            from .ros2_msgs import Ros2Encoder

            if thing not in self._ns:
                self._ns[thing] = unique_token(thing, set(self._ns.values()))
            enc = Ros2Encoder(thing, self._ns[thing], geom)
        self.things[thing] = m = ThingMapping(thing, enc, scene_hz=self.scene_hz)
        self.tds[thing] = td or {}
        return m

    def remove(self, thing: str) -> None:
        self.things.pop(thing, None)
        self.tds.pop(thing, None)
        for key in [k for k in self._raw if k[0] == thing]:
            del self._raw[key]

    def poses(self) -> dict[str, FramePose]:
        return {t: m.geom.pose for t, m in self.things.items() if m.geom is not None}

    def transforms(self, t_ns: int) -> Out | None:
        """Every skin's frame under the root frame (no skin: None)."""
        poses = self.poses()
        if not poses:
            return None
        if self.profile == "foxglove":
            from .foxglove_msgs import FoxgloveEncoder, transforms

            return Out(FoxgloveEncoder.tf_channel(), t_ns, transforms(poses, t_ns).encode())
        from .ros2_msgs import tf_static

        return tf_static(poses, t_ns)

    def raw_channel(self, thing: str, kind: int, name: str) -> Channel:
        key = (thing, kind, name)
        ch = self._raw.get(key)
        if ch is None:
            if self.profile == "foxglove":
                from .foxglove_msgs import FoxgloveEncoder

                schema = json.dumps(schema_of(self.tds.get(thing), kind, name)).encode()
                ch = FoxgloveEncoder.raw_channel(thing, kind, name, schema)
            else:
                found = self.things[thing].enc.channel("string", raw_topic("", kind, name).lstrip("/"))
                assert found is not None
                ch = found
            self._raw[key] = ch
        return ch

    def raw(self, rec: Record, wanted: Wanted = _all) -> list[Out]:
        """A record as it is, on its raw channel: Foxglove's JSON (every record), ROS 2's
        ``std_msgs/String`` (``record`` adds it only for a record nothing else carries)."""
        ch = self.raw_channel(rec.thing, rec.kind, rec.name)
        if not wanted(ch.topic):
            return []
        if self.profile == "ros2":
            from .ros2_msgs import ros_string

            return [Out(ch, rec.t_ns, ros_string(rec.data))]
        return [Out(ch, rec.t_ns, rec.data.encode())]

    def record(self, rec: Record, wanted: Wanted = _all) -> list[Out]:
        """Everything ``rec`` becomes: in Foxglove its raw form and its typed messages; in ROS 2 its
        typed messages, or its raw form when none carries it (not mapped, or unreadable)."""
        m = self.things.get(rec.thing)
        if m is None:
            return []
        unreadable = m.unreadable
        typed = m.record(rec, wanted)
        if self.profile == "ros2" and m.mapped(rec) and m.unreadable == unreadable:
            return typed
        return self.raw(rec, wanted) + typed

    def due(self, now_ns: int) -> list[Out]:
        out: list[Out] = []
        for m in self.things.values():
            out += m.due(now_ns)
        return out

    def deadlines(self) -> Iterable[int]:
        for m in self.things.values():
            for th in m.throttles.values():
                if th.deadline is not None:
                    yield th.deadline

