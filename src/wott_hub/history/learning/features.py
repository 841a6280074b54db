"""What a recorded Thing becomes in a learning dataset: its sources (recorded affordances) and features.

One source per recorded stream, each giving the features below for every frame (the value its latest
sample says, ``resample.py``), and the value before any sample (``rest``: at rest, no contact, no
action, a black image), which is what a skin that sent nothing is:

- ``skinDeformedDetection`` -> ``deformation``, float32 (N,) mm (``robotics.payloads.skin_packet``;
  nodes absent from a packet are at rest);
- ``skinDisplacement`` -> ``displacement``, float32 (N, 3) mm in the sensor frame
  (``robotics.raw_signals.displacement``);
- ``contactInformation`` -> ``contact_count`` int64 (1,), ``contact_centroid`` float32 (3,) mm (weighted
  by each contact's force magnitude), ``contact_force`` float32 (3,) N (the net force)
  (``robotics.payloads.contacts``);
- ``actionDetection`` -> ``action``, int64 (1,): 0 none, then the TD's enum in order;
- ``pressureGridRecorded`` -> ``pressure``, float32 (rows, cols) kPa, the recorded grid;
- ``rawImageRecorded`` -> ``observation.images.<id>.<camera>``, a video (H, W, 3) of the recorded PNGs,
  grey made RGB.

N is the Thing's ``skinNodes`` in their order (node ids in ``meta/wott.json``). The two skin streams'
packets stored packed come read as numbers (``history/numbers.py``: ``PackedRecord``), gathered a block
at a time; those stored as text go through the functions named above: the same values either way.
``--action THING.PROPERTY`` adds ``PropertySource``: any recorded property of numbers, flattened
(``action``, float32 (D,)).
"""

from __future__ import annotations

import binascii
import json
import re
from dataclasses import dataclass, field
from itertools import repeat
from operator import attrgetter
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from wott_hub.errors import InvalidInput
from wott_hub.robotics.payloads import contacts, load_json, skin_packet
from wott_hub.robotics.raw_signals import DISPLACEMENT_EVENT, displacement
from wott_hub.td.raw import PRESSURE_GRID_RECORDED, RAW_IMAGE_RECORDED

from ..numbers import PackedRecord, nodes_of
from .packets import contact_blocks

if TYPE_CHECKING:
    from wott_hub.events.record import Record
    from wott_hub.robotics.geometry import SkinGeometry

    from .resample import Held

__all__ = [
    "CameraSource",
    "ContactsSource",
    "DeformationSource",
    "DisplacementSource",
    "Feature",
    "GridSource",
    "PropertySource",
    "Source",
    "TouchActionSource",
    "block_values",
]

_NAME = attrgetter("name")
GRID_EVENT = PRESSURE_GRID_RECORDED
IMAGE_EVENT = RAW_IMAGE_RECORDED


@dataclass
class Feature:
    """One column of the dataset as lerobot declares it (``info.json``'s ``features``)."""

    key: str
    dtype: str
    shape: tuple[int, ...]
    names: list[str] | None = None
    info: dict[str, Any] | None = None

    def declared(self) -> dict[str, Any]:
        out: dict[str, Any] = {"dtype": self.dtype, "shape": list(self.shape), "names": self.names}
        if self.info is not None:
            out["info"] = self.info
        return out


@dataclass
class Source:
    """A recorded stream (``name``) of ``thing`` and the features each of its samples gives."""

    thing: str
    name: str
    age: str  # its component of the Thing's age column
    features: list[Feature] = field(default_factory=list)

    picky = False
    """Whether ``accepts`` refuses any record of ``name`` (``resample.Stream``)."""

    def accepts(self, rec: Record) -> bool:
        return True

    def rest(self) -> list[np.ndarray]:
        return [np.zeros(f.shape, np.float32 if f.dtype == "float32" else np.int64) for f in self.features]

    def decode(self, rec: Record) -> list[np.ndarray]:
        raise NotImplementedError

    def decode_many(self, recs: list[Record]) -> list[np.ndarray]:
        """The features of several samples, stacked (samples x shape); a source may do it at once."""
        table = [self.decode(r) for r in recs]
        return [np.stack([t[j] for t in table]) for j in range(len(self.features))]


def block_values(source: Source, held: Held) -> list[np.ndarray]:
    """The source's features at each frame of ``held``: each sample used decoded once."""
    used = np.unique(held.which[held.which >= 0])
    decoded = source.decode_many([held.samples[i] for i in used.tolist()]) if len(used) else None
    where = np.zeros(len(held.samples) + 1, np.int64)  # sample index + 1 -> row of the table (0: rest)
    where[used + 1] = np.arange(1, len(used) + 1)
    rows = where[held.which + 1]
    out = []
    for j, rest in enumerate(source.rest()):
        table = rest[None] if decoded is None else np.concatenate([rest[None], decoded[j]])
        out.append(table[rows])
    return out


class _NodeSource(Source):
    """A skin packet's nodes scattered onto the Thing's N nodes (those absent at rest), all the samples of
    a block at once."""

    def __init__(self, thing: str, name: str, age: str, feature: Feature, geom: SkinGeometry) -> None:
        super().__init__(thing, name, age, [feature])
        self.geom = geom

    def nodes(self, rec: Record) -> tuple[np.ndarray, np.ndarray]:
        """(node ids, their values) of one sample."""
        raise NotImplementedError

    def decode(self, rec: Record) -> list[np.ndarray]:
        return [self.decode_many([rec])[0][0]]

    def decode_many(self, recs: list[Record]) -> list[np.ndarray]:
        """Packets read as numbers (``history/numbers.py``) gathered at once, the others (stored as
        text) parsed by ``nodes``: the same values either way."""
        is_packed = np.fromiter(map(isinstance, recs, repeat(PackedRecord)), bool, len(recs))
        # (a PackedRecord's name is its packets')
        is_packed &= np.fromiter(map(self.name.__eq__, map(_NAME, recs)), bool, len(recs))
        at = np.flatnonzero(is_packed)
        packed = cast("list[PackedRecord]", [recs[i] for i in at.tolist()] if len(at) < len(recs) else recs)
        shape = self.features[0].shape[1:]
        if len(at):
            sample, ids, values = nodes_of(packed)
            sample = at[sample]
        else:
            sample, ids, values = np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)
        if len(at) < len(recs):
            parts = [(i, self.nodes(recs[i])) for i in np.flatnonzero(~is_packed).tolist()]
            sample = np.concatenate([sample, *(np.full(len(p[0]), i, np.int64) for i, p in parts)])
            ids = np.concatenate([ids, *(p[0] for _, p in parts)])
            values = np.concatenate([values.reshape(-1, *shape), *(p[1] for _, p in parts)])
        rows = self.geom.rows_of(ids)
        known_rows = rows >= 0
        out = np.zeros((len(recs), *self.features[0].shape), np.float32)
        out[sample[known_rows], rows[known_rows]] = values[known_rows]
        return [out]


def _prefix(thing: str) -> str:
    return f"observation.tactile.{thing}"


class DeformationSource(_NodeSource):
    def __init__(self, thing: str, geom: SkinGeometry) -> None:
        super().__init__(
            thing,
            "skinDeformedDetection",
            "deformation",
            Feature(f"{_prefix(thing)}.deformation", "float32", (len(geom.ids),), info={"unit": "mm"}),
            geom,
        )

    def nodes(self, rec: Record) -> tuple[np.ndarray, np.ndarray]:
        p = skin_packet(rec.data, rec.t_ns)
        return p.ids, p.intensity_mm


class DisplacementSource(_NodeSource):
    def __init__(self, thing: str, geom: SkinGeometry) -> None:
        super().__init__(
            thing,
            DISPLACEMENT_EVENT,
            "displacement",
            Feature(
                f"{_prefix(thing)}.displacement",
                "float32",
                (len(geom.ids), 3),
                names=["node", "axis"],
                info={"unit": "mm"},
            ),
            geom,
        )

    def nodes(self, rec: Record) -> tuple[np.ndarray, np.ndarray]:
        d = displacement(rec.data, rec.t_ns)
        return d.ids, d.displacement_mm


class ContactsSource(Source):
    def __init__(self, thing: str) -> None:
        p = _prefix(thing)
        super().__init__(
            thing,
            "contactInformation",
            "contacts",
            [
                Feature(f"{p}.contact_count", "int64", (1,), names=["count"]),
                Feature(f"{p}.contact_centroid", "float32", (3,), names=["x", "y", "z"], info={"unit": "mm"}),
                Feature(f"{p}.contact_force", "float32", (3,), names=["x", "y", "z"], info={"unit": "N"}),
            ],
        )

    def decode_many(self, recs: list[Record]) -> list[np.ndarray]:
        fast = contact_blocks([r.data for r in recs])
        if fast is None:
            return super().decode_many(recs)
        counts, loc, force = fast
        sample = np.repeat(np.arange(len(recs)), counts)
        weight = np.linalg.norm(force, axis=1)
        total = np.bincount(sample, weight, minlength=len(recs))
        unweighted = ~(total > 0)  # no force measured (or NaN): each contact counts once
        weight[unweighted[sample]] = 1.0
        total = np.bincount(sample, weight, minlength=len(recs))
        centroid = np.zeros((len(recs), 3))
        net = np.zeros((len(recs), 3))
        for axis in range(3):
            centroid[:, axis] = np.bincount(sample, loc[:, axis] * weight, minlength=len(recs))
            net[:, axis] = np.bincount(sample, force[:, axis], minlength=len(recs))
        touched = counts > 0
        centroid[touched] /= total[touched, None]
        return [counts[:, None], centroid.astype(np.float32), net.astype(np.float32)]

    def decode(self, rec: Record) -> list[np.ndarray]:
        c = contacts(rec.data)
        n = len(c.locations_mm)
        if n == 0:
            return self.rest()
        weight = np.linalg.norm(c.forces_n, axis=1)
        if not weight.sum() > 0:
            weight = np.ones(n)
        centroid = (c.locations_mm * weight[:, None]).sum(axis=0) / weight.sum()
        return [
            np.array([n], np.int64),
            centroid.astype(np.float32),
            c.forces_n.sum(axis=0).astype(np.float32),
        ]


class TouchActionSource(Source):
    """``actionDetection`` as a code: 0 none yet, then the TD's ``enum`` in order; an action the TD did
    not list gets the next code when first met (``classes`` is final once the export ends)."""

    def __init__(self, thing: str, enum: list[str]) -> None:
        self.classes = ["none", *[e for e in enum if isinstance(e, str) and e != "none"]]
        super().__init__(
            thing,
            "actionDetection",
            "action",
            [
                Feature(
                    f"{_prefix(thing)}.action",
                    "int64",
                    (1,),
                    names=["action"],
                    info={"classes": self.classes},
                )
            ],
        )

    def decode(self, rec: Record) -> list[np.ndarray]:
        try:
            action = json.loads(rec.data)
        except ValueError:
            action = rec.data
        action = action if isinstance(action, str) else json.dumps(action)
        if action not in self.classes:
            self.classes.append(action)
        return [np.array([self.classes.index(action)], np.int64)]


class GridSource(Source):
    def __init__(self, thing: str, rows: int, cols: int) -> None:
        super().__init__(
            thing,
            GRID_EVENT,
            "pressure",
            [
                Feature(
                    f"{_prefix(thing)}.pressure",
                    "float32",
                    (rows, cols),
                    names=["row", "col"],
                    info={"unit": "kPa"},
                )
            ],
        )

    def decode(self, rec: Record) -> list[np.ndarray]:
        shape = self.features[0].shape
        try:
            grid = np.asarray(json.loads(rec.data)["pressure"], dtype=np.float32)
        except (ValueError, KeyError, TypeError) as e:
            raise InvalidInput(f"{self.thing}: a {GRID_EVENT} record is not a grid ({e!r})") from None
        if grid.shape != shape:
            raise InvalidInput(f"{self.thing}: a pressure grid of {grid.shape} where the first was {shape}")
        return [grid]


_CAMERA = re.compile(r'"camera"\s*:\s*"((?:[^"\\]|\\.)*)"')


class CameraSource(Source):
    """One camera's recorded images, as the frames of a video (decoded by the video writer)."""

    def __init__(self, thing: str, camera: str, height: int, width: int) -> None:
        super().__init__(
            thing,
            IMAGE_EVENT,
            f"camera.{camera}",
            [
                Feature(
                    f"observation.images.{thing}.{camera}",
                    "video",
                    (height, width, 3),
                    names=["height", "width", "channels"],
                )
            ],
        )
        self.camera = camera

    picky = True

    def accepts(self, rec: Record) -> bool:
        found = _CAMERA.search(rec.data, 0, 400)  # the recorder writes the camera before the image
        if found is not None:
            return bool(json.loads(f'"{found.group(1)}"') == self.camera)
        try:
            return bool(json.loads(rec.data).get("camera") == self.camera)
        except (ValueError, AttributeError):
            return False

    def image(self, rec: Record) -> np.ndarray:
        """H x W x 3 uint8 of a recorded image (InvalidInput if it is not a PNG of the first one's size)."""
        import io

        from PIL import Image, UnidentifiedImageError

        h, w, _ = self.features[0].shape
        try:
            png = binascii.a2b_base64(load_json(rec.data)["image"])  # b64decode's, without its copy
            with Image.open(io.BytesIO(png)) as img:  # an RGB image as it is: no converted copy
                rgb = np.asarray(img if img.mode == "RGB" else img.convert("RGB"))
        except (ValueError, KeyError, TypeError, UnidentifiedImageError, OSError) as e:
            raise InvalidInput(
                f"{self.thing}: a {IMAGE_EVENT} record of {self.camera!r} is not a PNG ({e!r})"
            ) from None
        if rgb.shape != (h, w, 3):
            raise InvalidInput(
                f"{self.thing}: camera {self.camera!r} changed size ({rgb.shape[1]} x {rgb.shape[0]}, "
                f"first {w} x {h}): a video keeps one size"
            )
        return rgb


class PropertySource(Source):
    """``--action THING.PROPERTY``: a recorded value of numbers (a number, a list, an object: flattened
    in its order) as the ``action`` column."""

    def __init__(self, thing: str, name: str, first: Any) -> None:
        names = _flat_names(first, name)
        if not names:
            raise InvalidInput(
                f"--action {thing}.{name}: its value holds no number ({json.dumps(first)[:80]})"
            )
        super().__init__(
            thing, name, f"action.{name}", [Feature("action", "float32", (len(names),), names=names)]
        )

    def decode(self, rec: Record) -> list[np.ndarray]:
        try:
            values = _flat_values(json.loads(rec.data))
        except ValueError:
            values = []
        n = self.features[0].shape[0]
        if len(values) != n:
            raise InvalidInput(
                f"--action {self.thing}.{self.name}: a value of {len(values)} numbers where the first had {n}"
            )
        return [np.asarray(values, np.float32)]


def _flat_names(value: Any, at: str) -> list[str]:
    if isinstance(value, bool):
        return [at]
    if isinstance(value, int | float):
        return [at]
    if isinstance(value, list):
        return [n for i, v in enumerate(value) for n in _flat_names(v, f"{at}[{i}]")]
    if isinstance(value, dict):
        return [n for k, v in value.items() for n in _flat_names(v, f"{at}.{k}")]
    return []


def _flat_values(value: Any) -> list[float]:
    if isinstance(value, int | float):
        return [float(value)]
    if isinstance(value, list):
        return [x for v in value for x in _flat_values(v)]
    if isinstance(value, dict):
        return [x for v in value.values() for x in _flat_values(v)]
    return []
