"""ONNX displacement models: what the driver feeds them, what it expects back, checked at start-up.

The contract (docs/barrel-vision.md, "Bring your own model"):

Input, one of
- **markers**: one float32 input ``[batch, 1024]``, the image displacement
  (x, y, px, relative to the rest reference) of marker ``m`` (ring * 16 + ray)
  in camera ``c`` (0 bottom, 1 top) at column ``c * 512 + 2 * m + axis``; or
- **images**: the two grey camera frames resized to the model's H x W, as one
  input ``[batch, 2, H, W]`` or ``[batch, H, W, 2]``, or two inputs (bottom,
  top) of ``[batch, 1, H, W]``, ``[batch, H, W, 1]`` or ``[batch, H, W]``;
  float32 in [0, 1] or uint8 0-255. H and W must be fixed in the model.

Output: the first output, 1755 values per frame (the 585 free nodes in
ascending mesh index, x y z each, mm) or 2121 (all 707 nodes).

A model that does not fit is refused when the device opens (``ModelError``,
a ``DriverError``) with what it declares and what was expected, never
discovered frames later as a shape error. The check runs the model once on
a zero input, so dynamic shapes are checked too.

onnxruntime is imported when a model is loaded, never at module import.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from wott_vision.markers import as_gray

from wott_hub.plugin_api import DriverError

__all__ = ["DEFAULT_MODEL", "Contract", "DisplacementModel", "ModelError", "default_model_path"]

DEFAULT_MODEL = "barrel-local-ridge.onnx"
KINDS = ("auto", "markers", "images")
_DTYPES = {"tensor(float)": np.float32, "tensor(uint8)": np.uint8}


class ModelError(DriverError):
    """A displacement model that cannot be loaded or does not fit the driver's contract."""


def default_model_path() -> Path:
    return Path(str(resources.files("wott_driver_barrel") / "models" / DEFAULT_MODEL))


@dataclass(frozen=True)
class Contract:
    kind: str  # "markers" | "images"
    inputs: tuple[str, ...]
    dtype: type
    output: str
    all_nodes: bool  # output covers all nodes (else: free nodes only)
    image_hw: tuple[int, int] | None = None
    image_layout: str | None = None  # "nchw" | "nhwc" | "two-nchw" | "two-nhwc" | "two-hw"

    def describe(self) -> str:
        what = "all nodes" if self.all_nodes else "free nodes"
        if self.image_hw is None:  # a markers contract
            return f"markers -> {what}"
        h, w = self.image_hw
        return f"images {h}x{w} ({self.image_layout}, {np.dtype(self.dtype).name}) -> {what}"


# a model's input or output as onnxruntime declares it: a NodeArg (onnxruntime ships no types)
_NodeArg = Any
# what a model's inputs fit: kind, input names, element type, image (H, W) and layout (None for markers)
_Fit = tuple[str, tuple[str, ...], type, tuple[int, int] | None, str | None]


def _fmt(arg: _NodeArg) -> str:
    return f"{arg.name!r}: {arg.type} {list(arg.shape)}"


def _static(d: object) -> int | None:
    return d if isinstance(d, int) and d > 0 else None


class DisplacementModel:
    """A loaded model: ``predict_markers(features)`` or ``predict_images(images)`` -> (N, 3) mm."""

    def __init__(self, path: str | Path, *, n_features: int, n_cameras: int, free: np.ndarray,
                 expect: str = "auto", threads: int = 1) -> None:
        if expect not in KINDS:
            raise ModelError(f"model_input must be one of {', '.join(KINDS)}, got {expect!r}")
        self.path = Path(path)
        self.n_features = int(n_features)
        self.n_cameras = int(n_cameras)
        self.free = np.asarray(free, dtype=bool)
        self.n_nodes = len(self.free)
        self.n_free = int(self.free.sum())
        if not self.path.is_file():
            raise ModelError(f"model {self.path}: no such file")
        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = max(1, int(threads))
        so.inter_op_num_threads = 1
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        so.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=so,
                                                providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types for bad files
            raise ModelError(f"model {self.path}: cannot be loaded by onnxruntime: {e}") from None
        self._hw: tuple[int, int] = (0, 0)  # an image model's frame size and input layout
        self._layout = ""
        self.contract = self._check(expect)
        self.metadata = dict(self.session.get_modelmeta().custom_metadata_map)
        self._dry_run()

    # -- the contract ----------------------------------------------------------
    def _expected(self) -> str:
        return (f"marker motion (one float input [batch, {self.n_features}]) or camera images "
                f"(one input [batch, {self.n_cameras}, H, W] or [batch, H, W, {self.n_cameras}], or "
                f"{self.n_cameras} inputs [batch, 1, H, W] / [batch, H, W]; float32 or uint8)")

    def _check(self, expect: str) -> Contract:
        ins = self.session.get_inputs()
        outs = self.session.get_outputs()
        where = f"model {self.path.name}"
        if not outs:
            raise ModelError(f"{where}: has no output")
        declared = "; ".join(_fmt(a) for a in ins)
        for a in ins:
            if a.type not in _DTYPES:
                raise ModelError(f"{where}: input {_fmt(a)} has element type {a.type}; "
                                 f"expected float32 or uint8. The driver feeds {self._expected()}")
        contract = self._markers(ins) or self._images(ins)
        if contract is None:
            raise ModelError(f"{where}: inputs {declared} fit neither contract. The driver feeds "
                             f"{self._expected()}")
        kind, inputs, dtype, hw, layout = contract
        if hw is not None and layout is not None:  # what each frame's feeds are built to
            self._hw, self._layout = hw, layout
        if expect != "auto" and kind != expect:
            raise ModelError(f"{where}: setting model_input = {expect!r}, but its inputs ({declared}) "
                             f"take {kind}")
        out = outs[0]
        if out.type != "tensor(float)":
            raise ModelError(f"{where}: output {_fmt(out)} must be float32 (mm)")
        per_frame = [_static(d) for d in out.shape[1:]] if len(out.shape) > 1 else [_static(d)
                                                                                    for d in out.shape]
        all_nodes = False
        sizes = [d for d in per_frame if d is not None]
        if per_frame and len(sizes) == len(per_frame):
            n = int(np.prod(sizes))
            if n not in (3 * self.n_free, 3 * self.n_nodes):
                raise ModelError(self._bad_output(out.name, n, out.shape))
            all_nodes = n == 3 * self.n_nodes
        return Contract(kind, inputs, dtype, out.name, all_nodes, hw, layout)

    def _bad_output(self, name: str, n: int, shape: Sequence[Any]) -> str:
        return (f"model {self.path.name}: output {name!r} {list(shape)} gives {n} values per frame; "
                f"expected {3 * self.n_free} ({self.n_free} free nodes x 3, mm, ascending node index) "
                f"or {3 * self.n_nodes} ({self.n_nodes} nodes x 3)")

    def _markers(self, ins: Sequence[_NodeArg]) -> _Fit | None:
        if len(ins) == 1 and ins[0].type == "tensor(float)" and len(ins[0].shape) == 2:
            if _static(ins[0].shape[1]) == self.n_features:
                return "markers", (ins[0].name,), np.float32, None, None
        return None

    def _images(self, ins: Sequence[_NodeArg]) -> _Fit | None:
        c = self.n_cameras
        if len(ins) == 1 and len(ins[0].shape) == 4:
            s = [_static(d) for d in ins[0].shape]
            if s[1] == c and s[2] and s[3]:
                return "images", (ins[0].name,), _DTYPES[ins[0].type], (s[2], s[3]), "nchw"
            if s[3] == c and s[1] and s[2]:
                return "images", (ins[0].name,), _DTYPES[ins[0].type], (s[1], s[2]), "nhwc"
            return None
        if len(ins) == c and len({a.type for a in ins}) == 1:
            layouts: set[str] = set()
            sizes: set[tuple[int, int]] = set()
            for a in ins:
                s = [_static(d) for d in a.shape]
                if len(s) == 4 and s[1] == 1 and s[2] and s[3]:
                    layouts.add("two-nchw")
                    sizes.add((s[2], s[3]))
                elif len(s) == 4 and s[3] == 1 and s[1] and s[2]:
                    layouts.add("two-nhwc")
                    sizes.add((s[1], s[2]))
                elif len(s) == 3 and s[1] and s[2]:
                    layouts.add("two-hw")
                    sizes.add((s[1], s[2]))
                else:
                    return None
            if len(layouts) == 1 and len(sizes) == 1:
                return "images", tuple(a.name for a in ins), _DTYPES[ins[0].type], sizes.pop(), layouts.pop()
        return None

    def _dry_run(self) -> None:
        c = self.contract
        if c.kind == "markers":
            feeds = {c.inputs[0]: np.zeros((1, self.n_features), np.float32)}
        else:
            feeds = self._image_feeds(tuple(np.zeros(self._hw, np.uint8) for _ in range(self.n_cameras)))
        try:
            out = self.session.run([c.output], feeds)[0]
        except Exception as e:
            raise ModelError(f"model {self.path.name}: fails on a zero input of the declared shape: {e}") \
                from None
        n = int(np.asarray(out).size)
        if n not in (3 * self.n_free, 3 * self.n_nodes):
            raise ModelError(self._bad_output(c.output, n, np.asarray(out).shape))
        if not np.isfinite(out).all():
            raise ModelError(f"model {self.path.name}: returns NaN/Inf for the skin at rest")
        self.contract = replace(c, all_nodes=n == 3 * self.n_nodes)

    # -- inference -------------------------------------------------------------
    def _image_feeds(self, images: tuple[np.ndarray, ...]) -> dict[str, np.ndarray]:
        c = self.contract
        h, w = self._hw
        planes = []
        for img in images:
            g = as_gray(img)
            if g.shape != (h, w):
                import cv2

                g = cv2.resize(g, (w, h), interpolation=cv2.INTER_AREA)
            planes.append(g.astype(np.float32) / 255.0 if c.dtype == np.float32 else g.astype(np.uint8))
        if self._layout == "nchw":
            return {c.inputs[0]: np.stack(planes)[None]}
        if self._layout == "nhwc":
            return {c.inputs[0]: np.stack(planes, axis=-1)[None]}
        shape = {"two-nchw": (1, 1, h, w), "two-nhwc": (1, h, w, 1), "two-hw": (1, h, w)}[self._layout]
        return {name: p.reshape(shape) for name, p in zip(c.inputs, planes, strict=True)}

    def _to_nodes(self, out: np.ndarray) -> np.ndarray:
        flat = np.asarray(out, dtype=np.float64).reshape(-1)
        if self.contract.all_nodes:
            d = flat.reshape(self.n_nodes, 3).copy()
            d[~self.free] = 0.0  # clamped nodes do not move, whatever a model says
            return d
        d = np.zeros((self.n_nodes, 3))
        d[self.free] = flat.reshape(self.n_free, 3)
        return d

    def predict_markers(self, features: np.ndarray) -> np.ndarray:
        x = np.asarray(features, dtype=np.float32).reshape(1, self.n_features)
        return self._to_nodes(self.session.run([self.contract.output], {self.contract.inputs[0]: x})[0])

    def predict_images(self, images: tuple[np.ndarray, ...]) -> np.ndarray:
        return self._to_nodes(self.session.run([self.contract.output], self._image_feeds(images))[0])
