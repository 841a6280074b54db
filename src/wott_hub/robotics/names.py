"""Topic names and frame ids: one place, so a bag, an MCAP file and the live endpoint agree.

Foxglove topics keep the Thing id as it is (``/<thing>/scene/skin``: what the MCAP export always
wrote). ROS 2 names allow only letters, digits and ``_`` in a token, a token may not start with
a digit and ``__`` is reserved: ``ros_namespaces`` makes one token per Thing from its id
(``barrel-1`` -> ``barrel_1``), distinct within one bag. Frame ids are the Thing ids in both (tf2
frame ids are free strings), under one root frame ``ROOT_FRAME``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from wott_hub.events.record import KIND_PROPERTY

__all__ = ["ROOT_FRAME", "TF_TOPIC", "TF_STATIC_TOPIC", "raw_topic", "ros_namespaces", "ros_token",
           "unique_token"]

ROOT_FRAME = "wott_hub"
"""The parent of every sensor frame: the hub knows no robot, so a user attaches this frame to
one (a static transform publisher) and every skin follows."""

TF_TOPIC = "/tf"
"""Foxglove: ``foxglove.FrameTransforms`` placing each Thing's frame under ``ROOT_FRAME``."""

TF_STATIC_TOPIC = "/tf_static"
"""ROS 2: ``tf2_msgs/msg/TFMessage``, latched (transient local), as robot_state_publisher does."""

_BAD = re.compile(r"[^A-Za-z0-9_]+")


def raw_topic(thing: str, kind: int, name: str) -> str:
    """The Foxglove channel of an affordance's records as they are (JSON, the TD's schema)."""
    return f"/{thing}/{'properties' if kind == KIND_PROPERTY else 'events'}/{name}"


def ros_token(text: str) -> str:
    """``text`` as one ROS 2 name token: other characters become ``_``, no ``__``, never empty or
    starting with a digit."""
    token = re.sub(r"_{2,}", "_", _BAD.sub("_", text)).strip("_") or "thing"
    return f"t_{token}" if token[0].isdigit() else token


def unique_token(thing: str, taken: set[str]) -> str:
    """``ros_token(thing)``, or with ``_2``, ``_3``... if another Thing's namespace already has it."""
    base = token = ros_token(thing)
    n = 1
    while token in taken:
        n += 1
        token = f"{base}_{n}"
    return token


def ros_namespaces(things: Iterable[str]) -> dict[str, str]:
    """Thing id -> its ROS 2 namespace token, distinct within ``things``."""
    out: dict[str, str] = {}
    for thing in things:
        out[thing] = unique_token(thing, set(out.values()))
    return out
