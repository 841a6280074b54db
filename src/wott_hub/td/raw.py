"""The affordances of a device's raw signals: ``rawImage`` (cameras), ``pressureGrid`` (taxel arrays).

Declared only by a device that has them (its driver's ``ServesRawSignals``, described by
``tactile.raw.RawSignal``), never recorded unless the device opts in, encoded only for a reader
(docs/tactile-td.md, "Raw signals"). Each is a read-only property whose forms say the media
type (``td.forms``): ``rawImage`` as JSON (a base64 PNG string, what every WoT client can read),
``image/png``, ``image/jpeg``, ``application/x-npy`` and a ``multipart/x-mixed-replace`` stream a
browser ``<img>`` shows; ``pressureGrid`` as a JSON object, ``application/x-npy`` and an SSE
stream. ``uriVariables`` name the camera and the stream's rate (``maxRate``, per second), both
checked by the hub (a 400 problem+json naming the parameter).

A device that records its images (``RawSignal.record_hz``) also declares the event
``rawImageRecorded``: one recorded image (base64 PNG), replayed with the rest of history; one that
records its grid, ``pressureGridRecorded`` (the grid's JSON form), which learning exports read
(docs/learning.md).
"""

from __future__ import annotations

from typing import Any

from wott_hub.tactile.raw import GRID, IMAGE, RawSignal

__all__ = ["DEFAULT_RATE_HZ", "MAX_RATE_HZ", "PRESSURE_GRID", "PRESSURE_GRID_RECORDED", "RAW_IMAGE",
           "RAW_IMAGE_RECORDED", "RAW_TYPES", "raw_affordances", "raw_events"]

RAW_IMAGE = "rawImage"
PRESSURE_GRID = "pressureGrid"
RAW_IMAGE_RECORDED = "rawImageRecorded"
PRESSURE_GRID_RECORDED = "pressureGridRecorded"
RAW_TYPES = frozenset({"tac:RawImage", "tac:PressureGrid"})
"""The ``@type`` of a raw-signal property: live only (a replay's TD leaves them out)."""

MAX_RATE_HZ = 120.0
"""The highest ``maxRate`` a stream accepts (a camera's frame rate at most: more repeats frames)."""
DEFAULT_RATE_HZ = 10.0
"""A stream's rate when the reader sets none: the device's frame rate up to this (a live view)."""


def _max_rate(default: float) -> dict[str, Any]:
    return {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_RATE_HZ, "default": default, "unit": "Hz",
            "description": f"Streams only: at most this many values per second (default {default:g})."}


def _image(cameras: list[RawSignal]) -> dict[str, Any]:
    names = [c.name for c in cameras]
    sizes = ", ".join(f"{c.name} {c.shape[1]} x {c.shape[0]} px" if len(c.shape) == 2 else c.name
                      for c in cameras)
    rate = min((c.rate_hz for c in cameras if c.rate_hz), default=DEFAULT_RATE_HZ)
    return {
        "@type": "tac:RawImage",
        "title": RAW_IMAGE,
        "description": (f"The latest image of a camera ({sizes}): grey or RGB, 8 bits. Encoded only when "
                        "read: as JSON a base64 PNG string (the first camera), else as the form's "
                        "contentType says (PNG, JPEG, NumPy .npy H x W x C uint8, or a "
                        "multipart/x-mixed-replace JPEG stream at maxRate)."),
        "type": "string",
        "contentEncoding": "base64",
        "contentMediaType": "image/png",
        "readOnly": True,
        "observable": True,
        "uriVariables": {
            "camera": {"type": "string", "enum": names, "default": names[0],
                       "description": "Which camera (default the first)."},
            "maxRate": _max_rate(min(rate, DEFAULT_RATE_HZ)),
        },
    }


def _grid(grid: RawSignal) -> dict[str, Any]:
    rows, cols = grid.shape if len(grid.shape) == 2 else (0, 0)
    cell = {"type": "number", "unit": grid.unit} if grid.unit else {"type": "number"}
    return {
        "@type": "tac:PressureGrid",
        "title": PRESSURE_GRID,
        "description": (f"The latest {rows} x {cols} pressure grid (rows along y, kPa), read when asked: "
                        "JSON, NumPy .npy (float32 rows x cols) or an SSE stream at maxRate."),
        "type": "object",
        "properties": {
            "timeStamp": {"type": "integer", "minimum": 0, "unit": "ns"},
            "rows": {"type": "integer", "minimum": 0},
            "cols": {"type": "integer", "minimum": 0},
            "pressure": {"type": "array", "items": {"type": "array", "items": cell}},
        },
        "required": ["timeStamp", "rows", "cols", "pressure"],
        "readOnly": True,
        "observable": True,
        "uriVariables": {"maxRate": _max_rate(min(grid.rate_hz or DEFAULT_RATE_HZ, DEFAULT_RATE_HZ))},
    }


def raw_affordances(signals: tuple[RawSignal, ...]) -> dict[str, dict[str, Any]]:
    """The raw-signal properties of a device with these signals (no forms yet: ``td.forms`` writes them)."""
    out: dict[str, dict[str, Any]] = {}
    cameras = [s for s in signals if s.kind == IMAGE]
    grids = [s for s in signals if s.kind == GRID]
    if cameras:
        out[RAW_IMAGE] = _image(cameras)
    if grids:
        out[PRESSURE_GRID] = _grid(grids[0])
    return out


def raw_events(signals: tuple[RawSignal, ...]) -> dict[str, dict[str, Any]]:
    """``rawImageRecorded`` for a device that records images (a camera with ``record_hz`` > 0),
    ``pressureGridRecorded`` for one that records its grid."""
    out: dict[str, dict[str, Any]] = {}
    recorded = [s.name for s in signals if s.kind == IMAGE and s.record_hz > 0]
    if recorded:
        out[RAW_IMAGE_RECORDED] = {
            "@type": "tac:RawImageRecorded",
            "title": RAW_IMAGE_RECORDED,
            "description": ("A camera image recorded in history (the device opted in: record_raw_hz), a "
                            "base64 PNG, replayed with the rest of the device's records."),
            "data": {
                "type": "object",
                "properties": {
                    "timeStamp": {"type": "integer", "minimum": 0, "unit": "ns"},
                    "camera": {"type": "string", "enum": recorded},
                    "width": {"type": "integer", "minimum": 0},
                    "height": {"type": "integer", "minimum": 0},
                    "channels": {"type": "integer", "minimum": 1},
                    "image": {"type": "string", "contentEncoding": "base64", "contentMediaType": "image/png"},
                },
                "required": ["timeStamp", "camera", "image"],
            },
        }
    grids = [s for s in signals if s.kind == GRID and s.record_hz > 0]
    if grids:
        schema = _grid(grids[0])
        out[PRESSURE_GRID_RECORDED] = {
            "@type": "tac:PressureGridRecorded",
            "title": PRESSURE_GRID_RECORDED,
            "description": ("A pressure grid recorded in history (the device opted in: record_raw_hz), as "
                            "pressureGrid's JSON form, replayed with the rest of the device's records."),
            "data": {k: schema[k] for k in ("type", "properties", "required")},
        }
    return out
