"""The displacement field and the raw signals of issue 29, as this package takes them in.

Kept apart from the rest (the hub does not produce them yet) so that they plug into the mapping
with a small, visible addition:

- ``skinDisplacement`` records (an event, JSON): ``{timeStamp (ns), numOfDisplacedNodes,
  arrayOfDisplacedNodes: [{nodeID, displacement: {x, y, z} (mm)}]}``, the same nodes and frame as
  ``skinDeformedDetection``; read by ``displacement`` and mapped by ``mapping.ThingMapping.record``
  like any record.
- Camera images: an ``ImageFrame`` (camera name, time, and either encoded PNG/JPEG bytes or a raw
  H x W x C uint8 array), handed to ``mapping.ThingMapping.image`` (the live server's
  ``FoxgloveLive.image``), whatever carries them in (a recorded record, a camera's latest frame).
- A taxel array's pressure grid: a ``TaxelGrid`` (time, rows x cols values, their unit), handed to
  ``mapping.ThingMapping.taxels``. Its shape is this package's assumption (issue 29 names the grid
  but not its record).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wott_hub.errors import InvalidInput

from .payloads import load_json

__all__ = ["DISPLACEMENT_EVENT", "Displacement", "ImageFrame", "TaxelGrid", "displacement"]

DISPLACEMENT_EVENT = "skinDisplacement"

_PNG = b"\x89PNG\r\n\x1a\n"
_JPEG = b"\xff\xd8\xff"
RAW_ENCODINGS = {1: "mono8", 3: "rgb8", 4: "rgba8"}
"""Channels of a raw image -> its encoding name (ROS ``sensor_msgs/Image``, ``foxglove.RawImage``)."""


@dataclass(frozen=True)
class Displacement:
    t_ns: int
    ids: np.ndarray  # int64 node ids
    displacement_mm: np.ndarray  # N x 3, in the sensor frame


def displacement(text: str, t_ns: int) -> Displacement:
    """A ``skinDisplacement`` record's nodes; its ``timeStamp``, else the record's time."""
    try:
        d = load_json(text)
        nodes = d["arrayOfDisplacedNodes"]
        ids = np.array([int(n["nodeID"]) for n in nodes], dtype=np.int64)
        disp = np.array([(n["displacement"]["x"], n["displacement"]["y"], n["displacement"]["z"])
                         for n in nodes], dtype=np.float64).reshape(-1, 3)
        return Displacement(int(d.get("timeStamp", t_ns)), ids, disp)
    except (ValueError, KeyError, TypeError) as e:  # InvalidInput is a ValueError
        raise InvalidInput(f"not a {DISPLACEMENT_EVENT} packet ({e!r})") from None


@dataclass(frozen=True)
class ImageFrame:
    """One camera image. ``data``: PNG or JPEG bytes (sent as they are), or an H x W x C (or H x W)
    uint8 array with C in 1, 3 (RGB), 4 (RGBA) (sent raw)."""

    camera: str
    t_ns: int
    data: bytes | np.ndarray

    def __post_init__(self) -> None:
        if not self.camera or "/" in self.camera:
            raise InvalidInput(f"image: camera name {self.camera!r} must be non-empty, without '/'")
        if isinstance(self.data, bytes):
            if self.format is None:
                raise InvalidInput(f"image of {self.camera!r}: bytes that are neither PNG nor JPEG")
            return
        a = self.data
        if not isinstance(a, np.ndarray) or a.dtype != np.uint8 or a.ndim not in (2, 3) or (
                a.ndim == 3 and a.shape[2] not in RAW_ENCODINGS) or 0 in a.shape:
            raise InvalidInput(f"image of {self.camera!r}: expected PNG/JPEG bytes or an H x W x C uint8 "
                               "array (C = 1, 3 or 4)")

    @property
    def format(self) -> str | None:
        """``png``, ``jpeg`` (encoded bytes), ``raw`` (an array), None (bytes of neither)."""
        if isinstance(self.data, np.ndarray):
            return "raw"
        if self.data.startswith(_PNG):
            return "png"
        if self.data.startswith(_JPEG):
            return "jpeg"
        return None

    def raw(self) -> tuple[int, int, str, int, bytes]:
        """A raw image as (height, width, encoding, step, bytes)."""
        a = np.ascontiguousarray(self.data)
        h, w = a.shape[:2]
        c = 1 if a.ndim == 2 else a.shape[2]
        return h, w, RAW_ENCODINGS[c], w * c, a.tobytes()


@dataclass(frozen=True)
class TaxelGrid:
    """A taxel array's pressure grid: rows x cols values (row-major), in ``unit`` (kPa by default)."""

    t_ns: int
    values: np.ndarray
    unit: str = "kPa"

    def __post_init__(self) -> None:
        v = self.values
        if not isinstance(v, np.ndarray) or v.ndim != 2 or 0 in v.shape or not np.isfinite(v).all():
            raise InvalidInput("taxel grid: expected a finite rows x cols array")
