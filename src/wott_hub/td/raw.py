"""The affordances of a device's raw signals: ``rawImage`` (cameras), ``pressureGrid`` (taxel arrays), and the
vectors of each node: ``magneticField`` (magnetic skins, µT), ``taxelSignal`` (3-axis taxels' counts),
``taxelForce`` (their forces, N).

Declared only by a device that has them (its driver's ``ServesRawSignals``, described by
``tactile.raw.RawSignal``), never recorded unless the device opts in, encoded only for a reader
(docs/tactile-td.md, "Raw signals"). Each is a read-only property whose forms say the media
type (``td.forms``): ``rawImage`` as JSON (a base64 PNG string, what every WoT client can read),
``image/png``, ``image/jpeg``, ``application/x-npy`` and a ``multipart/x-mixed-replace`` stream a
browser ``<img>`` shows; ``pressureGrid`` as a JSON object, ``application/x-npy`` and an SSE
stream, and so do the vector properties. ``uriVariables`` name the camera (``camera``) or the grid or vector
signal (``signal``: ``raw`` as read, ``change`` less the baseline, as the driver names them) and the
stream's rate (``maxRate``, per second), all checked by the hub (a 400 problem+json naming the parameter).

A device that records its images (``RawSignal.record_hz``) also declares the event
``rawImageRecorded``: one recorded image (base64 PNG), replayed with the rest of history; one that
records its grid, ``pressureGridRecorded`` (the grid's JSON form), which learning exports read
(docs/learning.md).
"""

from __future__ import annotations

from typing import Any

from wott_hub.tactile.raw import GRID, IMAGE, VECTOR_TERMS, RawSignal

__all__ = ["DEFAULT_RATE_HZ", "DEPTH_MAP", "MAX_RATE_HZ", "PRESSURE_GRID", "PRESSURE_GRID_RECORDED",
           "RAW_IMAGE", "RAW_IMAGE_RECORDED", "RAW_PROPERTIES", "RAW_TYPES", "raw_affordances", "raw_events",
           "raw_property"]

RAW_IMAGE = "rawImage"
PRESSURE_GRID = "pressureGrid"
DEPTH_MAP = "depthMap"
RAW_IMAGE_RECORDED = "rawImageRecorded"
PRESSURE_GRID_RECORDED = "pressureGridRecorded"
_VECTORS = {  # term -> (@type, what its vectors are)
    "magneticField": ("tac:MagneticField", "the magnetic flux density at each magnetometer"),
    "taxelSignal": ("tac:TaxelSignal", "each 3-axis taxel's counts (x, y shear, z normal)"),
    "taxelForce": ("tac:TaxelForce", "the force on each 3-axis taxel, as its maker's calibration gives it"),
}
assert tuple(_VECTORS) == VECTOR_TERMS
RAW_PROPERTIES = frozenset({RAW_IMAGE, PRESSURE_GRID, DEPTH_MAP, *VECTOR_TERMS})
RAW_TYPES = frozenset({"tac:RawImage", "tac:PressureGrid", "tac:DepthMap",
                       *(t for t, _ in _VECTORS.values())})
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


def raw_property(signal: RawSignal) -> str:
    """The property that serves ``signal``."""
    if signal.kind == GRID:
        return signal.term or PRESSURE_GRID
    return {IMAGE: RAW_IMAGE}.get(signal.kind, signal.term)


def _which(signals: list[RawSignal]) -> dict[str, Any]:
    names = [s.name for s in signals]
    units = ", ".join(f"{s.name} {s.unit}" for s in signals)
    return {"type": "string", "enum": names, "default": names[0],
            "description": f"Which signal (default the first): {units}."}


def _grid(grids: list[RawSignal]) -> dict[str, Any]:
    grid = grids[0]
    rows, cols = grid.shape if len(grid.shape) == 2 else (0, 0)
    cell = {"type": "number", "unit": grid.unit} if grid.unit else {"type": "number"}
    return {
        "@type": "tac:PressureGrid",
        "title": PRESSURE_GRID,
        "description": (f"The latest {rows} x {cols} pressure grid (rows along y, {grid.unit or 'no unit'}), "
                        "read when asked: JSON, NumPy .npy (float32 rows x cols) or an SSE stream at "
                        "maxRate."),
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
        "uriVariables": {"signal": _which(grids),
                         "maxRate": _max_rate(min(grid.rate_hz or DEFAULT_RATE_HZ, DEFAULT_RATE_HZ))},
    }


def _depth_map(grids: list[RawSignal]) -> dict[str, Any]:
    """A gel's depth map (``term`` ``depthMap``): ``pressureGrid``'s form, its cells the indentation."""
    aff = _grid(grids)
    rows, cols = grids[0].shape if len(grids[0].shape) == 2 else (0, 0)
    aff["@type"], aff["title"] = "tac:DepthMap", DEPTH_MAP
    aff["description"] = (f"The latest {rows} x {cols} depth map of the gel (its indentation, mm; rows along "
                          "y, from the view's corner), from its depth calibration; read when asked: JSON, "
                          "NumPy .npy (float32 rows x cols) or an SSE stream at maxRate.")
    props = aff["properties"]
    props["depth"] = props.pop("pressure")
    aff["required"] = ["timeStamp", "rows", "cols", "depth"]
    return aff


def _vectors(term: str, signals: list[RawSignal]) -> dict[str, Any]:
    first = signals[0]
    n = first.shape[0] if first.shape else 0
    kind, what = _VECTORS[term]
    vector = {"type": "object", "properties": {a: {"type": "number", "unit": first.unit} for a in "xyz"},
              "required": ["x", "y", "z"]}
    return {
        "@type": kind,
        "title": term,
        "description": (f"The latest value of {what} ({n} nodes, in skinNodes order, {first.unit}), read "
                        "when asked: JSON, NumPy .npy (float32 N x 3) or an SSE stream at maxRate."),
        "type": "object",
        "properties": {
            "timeStamp": {"type": "integer", "minimum": 0, "unit": "ns"},
            "signal": {"type": "string", "enum": [s.name for s in signals]},
            "numOfNodes": {"type": "integer", "minimum": 0},
            "vectors": {"type": "array", "items": vector},
        },
        "required": ["timeStamp", "signal", "numOfNodes", "vectors"],
        "readOnly": True,
        "observable": True,
        "uriVariables": {"signal": _which(signals),
                         "maxRate": _max_rate(min(first.rate_hz or DEFAULT_RATE_HZ, DEFAULT_RATE_HZ))},
    }


def raw_affordances(signals: tuple[RawSignal, ...]) -> dict[str, dict[str, Any]]:
    """The raw-signal properties of a device with these signals (no forms yet: ``td.forms`` writes them)."""
    out: dict[str, dict[str, Any]] = {}
    cameras = [s for s in signals if s.kind == IMAGE]
    grids = [s for s in signals if s.kind == GRID and not s.term]
    depth = [s for s in signals if s.kind == GRID and s.term == DEPTH_MAP]
    if cameras:
        out[RAW_IMAGE] = _image(cameras)
    if grids:
        out[PRESSURE_GRID] = _grid(grids)
    if depth:
        out[DEPTH_MAP] = _depth_map(depth)
    for term in VECTOR_TERMS:
        vectors = [s for s in signals if s.term == term]
        if vectors:
            out[term] = _vectors(term, vectors)
    return out


def raw_events(signals: tuple[RawSignal, ...]) -> dict[str, dict[str, Any]]:
    """``rawImageRecorded`` for a device that records images (a camera with ``record_hz`` > 0),
    ``pressureGridRecorded`` for one that records a grid."""
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
    grids = [s for s in signals if s.kind == GRID and not s.term and s.record_hz > 0]
    if grids:
        schema = _grid(grids)
        out[PRESSURE_GRID_RECORDED] = {
            "@type": "tac:PressureGridRecorded",
            "title": PRESSURE_GRID_RECORDED,
            "description": ("A pressure grid recorded in history (the device opted in: record_raw_hz), as "
                            "pressureGrid's JSON form, replayed with the rest of the device's records."),
            "data": {k: schema[k] for k in ("type", "properties", "required")},
        }
    return out
