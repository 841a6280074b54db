"""What the mapping hands its consumers: a channel (topic, schema) and messages on it.

The same two types for both encodings, so an exporter or the live server registers a channel
the first time a message names it, whatever it carries.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["Channel", "Out"]


@dataclass(frozen=True)
class Channel:
    """``schema_name``: a Foxglove schema (``foxglove.SceneUpdate``) or a ROS 2 type
    (``sensor_msgs/msg/PointCloud2``); ``encoding`` and ``schema_encoding``: ``protobuf`` and
    ``protobuf``, ``json`` and ``jsonschema``, or ``cdr`` and ``ros2msg`` (the ROS 2 writer takes
    the definition from its type store: ``schema`` empty). ``latched``: a ROS 2 topic offered
    transient local (the mesh, ``/tf_static``), which ``ros2 bag play`` republishes as such."""

    topic: str
    schema_name: str
    encoding: str
    schema_encoding: str
    schema: bytes = b""
    latched: bool = False
    metadata: tuple[tuple[str, str], ...] = field(default=())


@dataclass(frozen=True)
class Out:
    """One message: its channel, its log time (ns) and its payload: encoded bytes (Foxglove) or a
    ``rosbags`` message object (ROS 2, serialised by the writer)."""

    channel: Channel
    t_ns: int
    payload: Any
