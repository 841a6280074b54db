"""A device's raw signals: what a camera or a taxel array measures before it becomes displacement.

A raw signal is described once, when the device opens (``RawSignal``), and read on demand
(``RawSample``: the latest array as the device gave it, not copied). The TD declares an
affordance per kind (``td.raw``); the hub encodes a sample only for a reader
(``runtime.raw``), never per frame. Pure description, no I/O: every layer may name it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from wott_hub.errors import InvalidInput

__all__ = ["GRID", "GRID_TERMS", "IMAGE", "KINDS", "VECTORS", "VECTOR_TERMS", "RawSample", "RawSignal"]

IMAGE = "image"
GRID = "grid"
VECTORS = "vectors"
KINDS = (IMAGE, GRID, VECTORS)
VECTOR_TERMS = ("magneticField", "taxelSignal", "taxelForce")
"""The properties a device's vector signals are served as (``td.raw``): a magnetometer's field, a 3-axis
taxel's counts, its force."""
GRID_TERMS = ("depthMap",)
"""The properties a grid may be served as instead of ``pressureGrid`` (its ``term``): a gel's depth map
(mm, issue 44)."""


@dataclass(frozen=True, slots=True)
class RawSignal:
    """One raw signal of a device.

    ``name``: how a reader names it (a camera: ``bottom``, ``top``, ``camera``; a grid:
    ``pressure``, ``raw`` and ``change``); ``kind``: ``"image"`` (H x W x C uint8, C 1 grey or 3 RGB),
    ``"grid"`` (rows x cols float, ``unit``) or ``"vectors"`` (N x 3 float, ``unit``: one per node,
    served as the property ``term``, one of ``VECTOR_TERMS``; a grid with a ``term``, one of
    ``GRID_TERMS``, is served as that property instead of ``pressureGrid``); ``shape``: (H, W),
    (rows, cols) or (N, 3), () when not known before the first frame (a real camera); ``rate_hz``: the
    device's frame rate (0: unknown); ``record_hz``: record a sample this often in history (0: never,
    the default; images and grids). Several grids or vector signals of one property are told apart by
    their names.
    """

    name: str
    kind: str
    shape: tuple[int, ...] = ()
    unit: str = ""
    rate_hz: float = 0.0
    record_hz: float = 0.0
    term: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InvalidInput(f"raw signal {self.name!r}: kind must be one of {', '.join(KINDS)}, "
                               f"got {self.kind!r}")
        if not self.name or not self.name.replace("-", "").replace("_", "").isalnum():
            raise InvalidInput(f"raw signal name must be letters, digits, - or _, got {self.name!r}")
        if (self.kind == VECTORS) != (self.term in VECTOR_TERMS) or (
                self.kind == GRID and self.term not in ("", *GRID_TERMS)):
            raise InvalidInput(f"raw signal {self.name!r}: vectors and only vectors name their property "
                               f"(term one of {', '.join(VECTOR_TERMS)}), but a grid may ("
                               f"{', '.join(GRID_TERMS)}); got {self.kind!r} {self.term!r}")
        if not (self.record_hz >= 0 and self.rate_hz >= 0):
            raise InvalidInput(f"raw signal {self.name!r}: rates must not be negative")


class RawSample(NamedTuple):
    """The latest value of a raw signal: the time of its frame (ns, the hub clock) and the array."""

    t_ns: int
    array: np.ndarray
