"""A device's raw signals as the hub serves them: sampled on demand, encoded for a reader, kept per frame.

Nothing here runs per frame. A reader (a property read, a stream at its ``maxRate``) asks
``RawSource.read(name, format)``: the driver's latest sample is fetched (in the hub's process,
or from the device's worker process over its pipe) and encoded in the format asked, once per
frame whatever the number of readers: the last encoding of each (signal, format) is kept with
its frame time, and readers arriving while it is being made wait for the same one. PNG and
JPEG are encoded in a thread (Pillow releases the GIL; a 640 x 480 PNG takes milliseconds, which
the event loop must not), .npy and JSON on the loop.

Formats (``FORMATS``): ``json`` (an image: a JSON string, base64 of its PNG; a grid: an object
``{timeStamp, rows, cols, pressure}``; vectors: ``{timeStamp, signal, numOfNodes, vectors}``), ``png``,
``jpeg``, ``npy`` (NumPy's .npy: an image H x W x C uint8, a grid rows x cols float32, vectors N x 3
float32). An image of the wrong dtype or shape from a driver is a
``DriverError`` naming the device: the reader gets a 502, the device and the hub carry on.

``RawRecorder``: a device that opted in (``RawSignal.record_hz``) has its images published as
``rawImageRecorded`` events at that rate, each a base64 PNG, and its grid as ``pressureGridRecorded``
(its JSON form), so recorded and replayed as any event, while the device runs.
"""

from __future__ import annotations

import asyncio
import base64
import io
import json
import logging
import time
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from wott_hub.errors import DriverError
from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.tactile.raw import GRID, IMAGE, VECTORS, RawSample, RawSignal
from wott_hub.td.raw import PRESSURE_GRID_RECORDED, RAW_IMAGE_RECORDED

if TYPE_CHECKING:
    from PIL.Image import Image

    from wott_hub.types import RecordSink

__all__ = ["CONTENT_TYPES", "FORMATS", "Encoded", "RawRecorder", "RawSource", "encode_sample"]

log = logging.getLogger("wott_hub.hub")

FORMATS = ("json", "png", "jpeg", "npy")
CONTENT_TYPES = {"json": "application/json", "png": "image/png", "jpeg": "image/jpeg",
                 "npy": "application/x-npy"}
JPEG_QUALITY = 90

Sampler = Callable[[str], Awaitable[RawSample | None]]
"""Fetch a signal's latest sample: the driver's ``raw_sample`` (here), or its worker's answer."""


class Encoded(NamedTuple):
    """One encoding of one sample: its frame time, the bytes, their media type."""

    t_ns: int
    body: bytes
    content_type: str


def _image(array: np.ndarray, device: str, name: str) -> np.ndarray:
    """H x W x C uint8 (C 1 or 3), or DriverError."""
    image = np.asarray(array)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (1, 3) or 0 in image.shape:
        raise DriverError(f"device {device!r}: camera {name!r} gave a {image.dtype} array of shape "
                          f"{image.shape}, not H x W (x 3) uint8")
    return image


def _pil(image: np.ndarray) -> Image:
    from PIL import Image  # Pillow: only when an image is encoded (docs/dependencies.md)

    return Image.fromarray(image[:, :, 0] if image.shape[2] == 1 else np.ascontiguousarray(image))


def _png(image: np.ndarray) -> bytes:
    out = io.BytesIO()
    _pil(image).save(out, format="PNG", compress_level=1)
    return out.getvalue()


def _jpeg(image: np.ndarray) -> bytes:
    out = io.BytesIO()
    _pil(image).save(out, format="JPEG", quality=JPEG_QUALITY)
    return out.getvalue()


def _npy(array: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.save(out, np.ascontiguousarray(array), allow_pickle=False)
    return out.getvalue()


def encode_sample(signal: RawSignal, sample: RawSample, fmt: str, device: str = "") -> bytes:
    """The bytes of ``sample`` of ``signal`` in ``fmt`` (one of ``FORMATS``)."""
    if signal.kind == IMAGE:
        image = _image(sample.array, device, signal.name)
        if fmt == "png":
            return _png(image)
        if fmt == "jpeg":
            return _jpeg(image)
        if fmt == "npy":
            return _npy(image)
        return json.dumps(base64.b64encode(_png(image)).decode("ascii")).encode()
    grid = np.asarray(sample.array, np.float64)
    vectors = signal.kind == VECTORS
    if grid.ndim != 2 or (vectors and grid.shape[1] != 3) or not np.isfinite(grid).all():
        raise DriverError(f"device {device!r}: {signal.kind} {signal.name!r} is not a finite "
                          f"{'N x 3' if vectors else 'rows x cols'} array")
    if fmt == "npy":
        return _npy(grid.astype(np.float32))
    if fmt != "json":
        raise ValueError(f"a {signal.kind} signal has no {fmt} form")
    if vectors:
        xyz = [{"x": x, "y": y, "z": z} for x, y, z in np.round(grid, 4).tolist()]
        return json.dumps({"timeStamp": sample.t_ns, "signal": signal.name, "numOfNodes": len(xyz),
                           "vectors": xyz}, separators=(",", ":")).encode()
    rows, cols = grid.shape
    values = np.round(grid, 3).tolist()
    key = "depth" if signal.term == "depthMap" else "pressure"  # td.raw: a depth map's cells are depths
    return json.dumps({"timeStamp": sample.t_ns, "rows": rows, "cols": cols, key: values},
                      separators=(",", ":")).encode()


class RawSource:
    """The raw signals of one device, read through ``sample`` and encoded at most once per frame and
    format (the ``types.RawReads`` the servient serves).

    A sample is fetched at most twice per frame period of its signal whatever the number of readers
    (issue 48: each stream fetched its own, a copy of the image from the driver or its worker, and 200
    streams halved the camera's own rate): readers within half a period share the last sample, and
    readers arriving while one is fetched wait for it."""

    def __init__(self, device: str, signals: tuple[RawSignal, ...], sample: Sampler) -> None:
        self.device = device
        self.signals = signals
        self.by_name = {s.name: s for s in signals}
        self._sample = sample
        self._last: dict[tuple[str, str], Encoded] = {}
        self._making: dict[tuple[str, str, int], asyncio.Future[Encoded]] = {}
        self._sampled: dict[str, tuple[float, RawSample | None]] = {}  # name -> (when fetched, the sample)
        self._fetching: dict[str, asyncio.Future[RawSample | None]] = {}
        self.encoded = 0  # encodings made (what readers cost; tests and the hub's counters)

    async def _shared_sample(self, name: str, signal: RawSignal) -> RawSample | None:
        fresh_s = 0.5 / signal.rate_hz if signal.rate_hz else 0.0
        got = self._sampled.get(name)
        if got is not None and time.monotonic() - got[0] < fresh_s:
            return got[1]
        pending = self._fetching.get(name)
        if pending is not None:
            return await asyncio.shield(pending)
        fut: asyncio.Future[RawSample | None] = asyncio.get_running_loop().create_future()
        self._fetching[name] = fut
        try:
            sample = await self._sample(name)
        except BaseException as e:
            fut.set_exception(e)
            fut.exception()  # retrieved: a reader that was not waiting must not log it as lost
            raise
        finally:
            self._fetching.pop(name, None)
        self._sampled[name] = (time.monotonic(), sample)
        fut.set_result(sample)
        return sample

    async def read(self, name: str, fmt: str) -> Encoded | None:
        """Signal ``name``'s latest sample in ``fmt``; None before its first frame. ``DriverError`` if
        the driver (or its worker) fails to give one."""
        signal = self.by_name[name]
        sample = await self._shared_sample(name, signal)
        if sample is None:
            return None
        key = (name, fmt)
        last = self._last.get(key)
        if last is not None and last.t_ns == sample.t_ns:
            return last
        making_key = (name, fmt, sample.t_ns)
        pending = self._making.get(making_key)
        if pending is not None:  # another reader is encoding this very frame: share its result
            return await asyncio.shield(pending)
        fut: asyncio.Future[Encoded] = asyncio.get_running_loop().create_future()
        self._making[making_key] = fut
        try:
            if fmt in ("png", "jpeg") or (fmt == "json" and signal.kind == IMAGE):
                body = await asyncio.to_thread(encode_sample, signal, sample, fmt, self.device)
            else:
                body = encode_sample(signal, sample, fmt, self.device)
            out = Encoded(sample.t_ns, body, CONTENT_TYPES[fmt])
            self.encoded += 1
            current = self._last.get(key)
            if current is None or current.t_ns <= out.t_ns:
                self._last[key] = out
            fut.set_result(out)
            return out
        except BaseException as e:
            fut.set_exception(e)
            fut.exception()  # retrieved: readers waiting on it get it; none waiting is fine too
            raise
        finally:
            del self._making[making_key]


class RawRecorder:
    """Publishes the signals that opted in (``record_hz`` > 0) into ``sink``, each at its rate, until
    cancelled: images as ``rawImageRecorded``, grids as ``pressureGridRecorded``."""

    def __init__(self, thing: str, source: RawSource, sink: RecordSink) -> None:
        self.thing = thing
        self.source = source
        self.sink = sink
        self.recorded = 0

    @property
    def signals(self) -> list[RawSignal]:
        return [s for s in self.source.signals if s.kind in (IMAGE, GRID) and s.record_hz > 0]

    async def run(self) -> None:
        await asyncio.gather(*(self._signal(s) for s in self.signals))

    async def _signal(self, signal: RawSignal) -> None:
        period = 1.0 / signal.record_hz
        last = -1
        loop = asyncio.get_running_loop()
        due = loop.time()
        while True:
            due += period
            await asyncio.sleep(max(0.0, due - loop.time()))
            try:
                enc = await self.source.read(signal.name, "png" if signal.kind == IMAGE else "json")
            except DriverError as e:
                log.warning("%s: not recorded: %s", self.thing, e)
                continue
            if enc is None or enc.t_ns == last:  # no frame yet, or none since the last recorded
                continue
            last = enc.t_ns
            if signal.kind == GRID:  # its JSON form as it is
                if self.sink.wants(self.thing, KIND_EVENT, PRESSURE_GRID_RECORDED):
                    self.sink.put(Record(self.thing, 0, KIND_EVENT, PRESSURE_GRID_RECORDED, enc.t_ns,
                                         enc.body.decode()))
                    self.recorded += 1
                continue
            if not self.sink.wants(self.thing, KIND_EVENT, RAW_IMAGE_RECORDED):
                continue
            h, w, c = _shape_of_png(enc.body)
            data = json.dumps({"timeStamp": enc.t_ns, "camera": signal.name, "width": w, "height": h,
                               "channels": c, "image": base64.b64encode(enc.body).decode("ascii")},
                              separators=(",", ":"))
            self.sink.put(Record(self.thing, 0, KIND_EVENT, RAW_IMAGE_RECORDED, enc.t_ns, data))
            self.recorded += 1


def _shape_of_png(png: bytes) -> tuple[int, int, int]:
    """(height, width, channels) from a PNG's IHDR chunk (colour type 0: grey, 2: RGB)."""
    width = int.from_bytes(png[16:20], "big")
    height = int.from_bytes(png[20:24], "big")
    return height, width, 3 if png[25] == 2 else 1
