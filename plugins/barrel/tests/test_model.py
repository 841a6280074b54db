"""The model contract: what fits is accepted (and runs), what does not is refused at start-up, clearly."""

import numpy as np
import pytest
from onnx import TensorProto, helper, numpy_helper, save_model
from wott_driver_barrel.model import DisplacementModel, ModelError, default_model_path
from wott_driver_barrel.settings import open_barrel

from wott_hub.drivers.base import DriverError

F, N_FREE, N_NODES = 1024, 585, 707


def _save(tmp_path, name, nodes, inputs, outputs, inits=()):
    graph = helper.make_graph(nodes, name, inputs, outputs, list(inits))
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    path = tmp_path / f"{name}.onnx"
    save_model(model, str(path))
    return path


def _vi(name, elem, shape):
    return helper.make_tensor_value_info(name, elem, shape)


def _linear(tmp_path, name, n_in, n_out, in_shape=None, out_shape=None, value=0.01):
    w = np.full((n_in, n_out), value, np.float32)
    return _save(tmp_path, name, [helper.make_node("MatMul", ["x", "w"], ["y"])],
                 [_vi("x", TensorProto.FLOAT, in_shape or ["batch", n_in])],
                 [_vi("y", TensorProto.FLOAT, out_shape or ["batch", n_out])],
                 [numpy_helper.from_array(w, "w")])


def _image_model(tmp_path, name, in_shape, elem=TensorProto.FLOAT, n_out=3 * N_FREE, two=False):
    """Mean brightness of the frames -> a uniform displacement (a stand-in for a learned net)."""
    inits = [numpy_helper.from_array(np.full((1, n_out), 0.5, np.float32), "w"),
             numpy_helper.from_array(np.array([1, 1], np.int64), "shape")]
    names = ["a", "b"] if two else ["x"]
    nodes, means = [], []
    for nm in names:
        src = nm
        if elem != TensorProto.FLOAT:
            nodes.append(helper.make_node("Cast", [nm], [nm + "_f"], to=TensorProto.FLOAT))
            src = nm + "_f"
        nodes.append(helper.make_node("ReduceMean", [src], [nm + "_m"], keepdims=0))
        means.append(nm + "_m")
    if two:
        nodes.append(helper.make_node("Add", means, ["m"]))
    else:
        nodes.append(helper.make_node("Identity", means, ["m"]))
    nodes += [helper.make_node("Reshape", ["m", "shape"], ["m2"]),
              helper.make_node("MatMul", ["m2", "w"], ["y"])]
    return _save(tmp_path, name, nodes, [_vi(nm, elem, in_shape) for nm in names],
                 [_vi("y", TensorProto.FLOAT, [1, n_out])], inits)


def _load(path, expect="auto"):
    free = np.zeros(N_NODES, bool)
    free[:N_FREE] = True
    return DisplacementModel(path, n_features=F, n_cameras=2, free=free, expect=expect)


def test_default_model_is_small_and_fits_the_contract():
    path = default_model_path()
    assert path.stat().st_size < 1_000_000
    m = _load(path)
    assert m.contract.kind == "markers" and not m.contract.all_nodes
    assert "accuracy" in m.metadata["wott.model"]
    assert not m.predict_markers(np.zeros(F)).any() or np.abs(m.predict_markers(np.zeros(F))).max() < 0.05


@pytest.mark.parametrize("n_out,all_nodes", [(3 * N_FREE, False), (3 * N_NODES, True)])
def test_marker_models_with_either_output_size_are_accepted(tmp_path, n_out, all_nodes):
    m = _load(_linear(tmp_path, "lin", F, n_out))
    assert m.contract.kind == "markers" and m.contract.all_nodes is all_nodes
    d = m.predict_markers(np.ones(F))
    assert d.shape == (N_NODES, 3)
    np.testing.assert_allclose(d[:N_FREE], 10.24, rtol=1e-5)
    assert not d[N_FREE:].any()  # clamped nodes stay put even if a model says otherwise


@pytest.mark.parametrize("shape,elem,two,layout", [
    ([1, 2, 256, 256], TensorProto.FLOAT, False, "nchw"),
    ([1, 256, 256, 2], TensorProto.UINT8, False, "nhwc"),
    ([1, 1, 96, 128], TensorProto.FLOAT, True, "two-nchw"),
    ([1, 96, 128], TensorProto.UINT8, True, "two-hw"),
])
def test_image_models_are_accepted_and_fed_resized_frames(tmp_path, shape, elem, two, layout):
    m = _load(_image_model(tmp_path, "img", shape, elem, two=two))
    assert m.contract.kind == "images" and m.contract.image_layout == layout
    frames = (np.full((480, 640), 255, np.uint8), np.full((480, 640), 255, np.uint8))
    d = m.predict_images(frames)
    scale = 1.0 if elem == TensorProto.FLOAT else 255.0
    expected = 0.5 * scale * (2 if two else 1)
    np.testing.assert_allclose(d[:N_FREE], expected, rtol=1e-4)


@pytest.mark.parametrize("maker,message", [
    (lambda p: _linear(p, "wrong_in", 1000, 3 * N_FREE), "fit neither contract"),
    (lambda p: _linear(p, "wrong_out", F, 1000), "gives 1000 values per frame; expected 1755"),
    (lambda p: _linear(p, "wrong_out_dyn", F, 1000, out_shape=["batch", "n"]), "expected 1755"),
    (lambda p: _image_model(p, "three_cams", [1, 3, 256, 256]), "fit neither contract"),
    (lambda p: _image_model(p, "dynamic_hw", [1, 2, "h", "w"]), "fit neither contract"),
    (lambda p: _image_model(p, "int64", [1, 2, 64, 64], TensorProto.INT64), r"element type tensor\(int64\)"),
])
def test_mismatched_models_are_refused_with_what_was_expected(tmp_path, maker, message):
    with pytest.raises(ModelError, match=message) as info:
        _load(maker(tmp_path))
    assert "1024" in str(info.value) or "1755" in str(info.value)


def test_declared_kind_must_match(tmp_path):
    path = _image_model(tmp_path, "img", [1, 2, 64, 64])
    with pytest.raises(ModelError, match="model_input = 'markers'"):
        _load(path, expect="markers")
    assert _load(path, expect="images").contract.kind == "images"


def test_nan_model_and_junk_files_are_refused(tmp_path):
    nan = np.full((F, 3 * N_FREE), np.nan, np.float32)
    path = _save(tmp_path, "nan", [helper.make_node("MatMul", ["x", "w"], ["y"])],
                 [_vi("x", TensorProto.FLOAT, [1, F])], [_vi("y", TensorProto.FLOAT, [1, 3 * N_FREE])],
                 [numpy_helper.from_array(nan, "w")])
    with pytest.raises(ModelError, match="NaN"):
        _load(path)
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"definitely not protobuf")
    with pytest.raises(ModelError, match="cannot be loaded"):
        _load(junk)
    with pytest.raises(ModelError, match="no such file"):
        _load(tmp_path / "missing.onnx")


def test_the_device_refuses_a_bad_user_model_when_it_opens(tmp_path):
    bad = _linear(tmp_path, "bad", F, 42)
    with pytest.raises(DriverError, match="42 values per frame"):
        open_barrel("b1", {"model": str(bad)})
    good = _image_model(tmp_path, "img", [1, 2, 256, 256])
    driver = open_barrel("b1", {"model": str(good), "realtime": False})
    assert driver.estimator.model.contract.kind == "images"
