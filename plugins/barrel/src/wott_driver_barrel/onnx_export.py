"""Writing displacement models as ONNX with the ``onnx`` helper API (no deep-learning framework).

Only the training script, the benchmark and the tests use this (``onnx`` is
in the dev dependency group); the driver needs ``onnxruntime`` alone.

Graph of the local ridge model, for a batch of B frames::

    marker_px [B, 1024] --Gather(axis 1, index [585, K])--> [B, 585, K]
        --Unsqueeze(2)--> [B, 585, 1, K] --MatMul(weight [585, K, 3])--> [B, 585, 1, 3]
        --Reshape--> [B, 1755] --Add(bias)--> free_node_displacement_mm [B, 1755]
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .training import LocalRidge

if TYPE_CHECKING:
    import onnx

__all__ = ["INPUT_NAME", "OUTPUT_NAME", "dense_model", "local_ridge_model", "save"]

INPUT_NAME = "marker_px"
OUTPUT_NAME = "free_node_displacement_mm"
OPSET = 17
IR_VERSION = 8  # readable by onnxruntime >= 1.10


def _finish(graph: onnx.GraphProto, metadata: dict[str, str]) -> onnx.ModelProto:
    from onnx import checker, helper

    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="wott-driver-barrel")
    model.ir_version = IR_VERSION
    for key, value in metadata.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    checker.check_model(model)
    return model


def local_ridge_model(m: LocalRidge, n_features: int,
                      metadata: dict[str, str] | None = None) -> onnx.ModelProto:
    from onnx import TensorProto, helper, numpy_helper

    n_free, k = m.index.shape
    n_out = 3 * n_free
    inits = [
        numpy_helper.from_array(m.index.astype(np.int32), "index"),
        numpy_helper.from_array(m.weight.astype(np.float32), "weight"),
        numpy_helper.from_array(m.bias.astype(np.float32), "bias"),
        numpy_helper.from_array(np.array([2], np.int64), "axis2"),
        numpy_helper.from_array(np.array([-1, n_out], np.int64), "out_shape"),
    ]
    nodes = [
        helper.make_node("Gather", [INPUT_NAME, "index"], ["gathered"], axis=1),
        helper.make_node("Unsqueeze", ["gathered", "axis2"], ["rows"]),
        helper.make_node("MatMul", ["rows", "weight"], ["per_node"]),
        helper.make_node("Reshape", ["per_node", "out_shape"], ["flat"]),
        helper.make_node("Add", ["flat", "bias"], [OUTPUT_NAME]),
    ]
    graph = helper.make_graph(
        nodes, "barrel_local_ridge",
        [helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, ["batch", n_features])],
        [helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, ["batch", n_out])],
        inits,
    )
    meta = {"wott.input": "marker_px", "wott.model": json.dumps(m.info, sort_keys=True)}
    meta.update(metadata or {})
    return _finish(graph, meta)


def dense_model(w: np.ndarray, b: np.ndarray, metadata: dict[str, str] | None = None) -> onnx.ModelProto:
    """x @ W + b: the dense ridge map (benchmark comparison)."""
    from onnx import TensorProto, helper, numpy_helper

    n_in, n_out = w.shape
    graph = helper.make_graph(
        [helper.make_node("MatMul", [INPUT_NAME, "W"], ["xw"]),
         helper.make_node("Add", ["xw", "b"], [OUTPUT_NAME])],
        "barrel_dense_ridge",
        [helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, ["batch", n_in])],
        [helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, ["batch", n_out])],
        [numpy_helper.from_array(w.astype(np.float32), "W"),
         numpy_helper.from_array(b.astype(np.float32), "b")],
    )
    return _finish(graph, {"wott.input": "marker_px", **(metadata or {})})


def save(model: onnx.ModelProto, path: str | Path) -> Path:
    import onnx

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    onnx.save_model(model, str(path))
    return path
