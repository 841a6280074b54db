"""The ``skinDisplacement`` record (issue 29): the pipeline's numbers, its JSON text and binary form made
only when read, across a pipe without its text, the norms equal to the frame's intensities."""

from __future__ import annotations

import json
import pickle
import struct

import numpy as np
import pytest

from wott_hub.events.fields import (
    CONTENT_TYPE,
    MAGIC,
    SKIN_DISPLACEMENT,
    FieldArrays,
    FieldRecord,
    displacement_json,
    field_of_text,
    packet_bytes,
)
from wott_hub.events.plane import EventPlane
from wott_hub.events.record import KIND_EVENT, encode
from wott_hub.examples import example_device
from wott_hub.runtime.payloads import displacement_rows
from wott_hub.runtime.pipeline import SKIN_DEFORMED, DevicePipeline
from wott_hub.tactile import FrameProcessor, TactileFrame
from wott_hub.tactile.indentation import Indenter, indent

QUANTUM_BOUND_MM = (3**0.5 / 2 + 0.5) / 1000  # both rounded to 1 µm: docs/tactile-td.md


def _frames(shape: str, n: int, seed: int = 3):
    """Random multi-contact presses with some shear, every 6th frame at rest."""
    desc = example_device(shape)
    mesh = desc.mesh
    rng = np.random.default_rng(seed)
    for t in range(1, n):
        if t % 6 == 0:
            yield desc, TactileFrame(t, np.zeros_like(mesh.nodes))
            continue
        presses = [Indenter(mesh.nodes[rng.choice(mesh.free_indices)], float(rng.uniform(0.2, 5.0)),
                            float(rng.uniform(2.0, 9.0)), rng.normal(0, 0.8, 3))
                   for _ in range(int(rng.integers(1, 4)))]
        yield desc, TactileFrame(t, indent(mesh, presses))


@pytest.mark.parametrize("shape", ["flat", "barrel"])
def test_each_vector_is_its_nodes_displacement_and_its_norm_the_frames_intensity(shape):
    proc = None
    releases = 0
    for desc, frame in _frames(shape, 120):
        proc = proc or FrameProcessor(desc.mesh)
        res = proc.process(frame)
        if not res.packet_due:
            continue
        field = FieldArrays.of(*displacement_rows(res, frame.displacement))
        assert field.ids.tolist() == res.deformed_nodes.tolist()  # the same nodes, the same order
        if res.is_release:
            releases += 1
            assert not field.micro.any()  # the final packet at rest: zero vectors
            continue
        np.testing.assert_allclose(field.mm(), frame.displacement[res.deformed_nodes], atol=0.5e-3)
        norms = np.linalg.norm(field.mm(), axis=1)
        assert np.abs(norms - res.intensity).max() <= QUANTUM_BOUND_MM
    assert releases > 3


def test_the_text_is_encode_of_the_payload_and_the_binary_form_has_the_documented_layout():
    field = FieldArrays.of([3, 7, 700], [[0.1234, -0.0005, 1.0], [0.0, 0.0, -2.5], [12.3456, 1e-4, -0.0015]])
    text = displacement_json(42, field)
    payload = {"timeStamp": 42, "numOfDisplacedNodes": 3, "arrayOfDisplacedNodes": [
        {"nodeID": i, "displacement": dict(zip("xyz", v, strict=True))}
        for i, v in zip(field.ids.tolist(), field.mm().tolist(), strict=True)]}
    assert text == encode(payload)
    assert json.loads(text)["arrayOfDisplacedNodes"][0]["displacement"] == {"x": 0.123, "y": 0.0, "z": 1.0}
    blob = packet_bytes(9, 42, field)
    magic, n, seq, ts = struct.unpack_from("<4sIQq", blob)
    assert (magic, n, seq, ts, len(blob)) == (MAGIC, 3, 9, 42, 24 + 16 * 3)
    assert np.frombuffer(blob, "<u4", 3, 24).tolist() == [3, 7, 700]
    vectors = np.frombuffer(blob, "<f4", 9, 36).reshape(3, 3)
    np.testing.assert_array_equal(vectors, field.mm().astype(np.float32))
    assert CONTENT_TYPE == "application/vnd.wott.skin-displacement"
    assert field_of_text(text) is not None and field_of_text(text).micro.tolist() == field.micro.tolist()
    assert field_of_text(text.replace('"x":0.123', '"x":0.1230')) is None  # not the hub's exact form
    assert field_of_text("[1, 2]") is None and field_of_text("not json") is None


class _Sink:
    def __init__(self, wanted: set[str]) -> None:
        self.wanted, self.out = wanted, []

    def wants(self, thing: str, kind: int, name: str) -> bool:
        return name in self.wanted

    def put(self, rec) -> None:
        self.out.append(rec)


def test_the_pipeline_makes_the_record_only_when_wanted_and_as_numbers():
    desc = example_device("flat")
    d = indent(desc.mesh, [Indenter(desc.mesh.nodes[desc.mesh.free_indices[100]], 1.0, 4.0)])
    pipeline = DevicePipeline("pad", None, FrameProcessor(desc.mesh))  # type: ignore[arg-type]
    res = pipeline.processor.process(TactileFrame(1, d))
    nobody = _Sink({SKIN_DEFORMED})
    pipeline.records(res, 0, nobody, d)
    assert [r.name for r in nobody.out] == [SKIN_DEFORMED]  # nobody wants the vectors: not even made
    wanted = _Sink({SKIN_DEFORMED, SKIN_DISPLACEMENT})
    pipeline.records(res, 0, wanted, d)
    rec = wanted.out[-1]
    assert type(rec) is FieldRecord and rec.name == SKIN_DISPLACEMENT and not rec.text_built
    assert json.loads(rec.data)["numOfDisplacedNodes"] == len(res.deformed_nodes) and rec.text_built


def test_a_record_crosses_a_pipe_as_numbers_and_its_text_is_written_once_read():
    rows = (np.arange(20), np.random.default_rng(1).normal(0, 1, (20, 3)))
    field = FieldArrays.of(*rows)
    rec = FieldRecord("pad", 0, 10**18, rows=rows)  # as the pipeline makes it: not quantised yet
    back = pickle.loads(pickle.dumps(rec))  # a worker's pipe, the history process's
    assert rec.wire()[0] == "mm" and rec._field is None  # quantised on the other side, when needed
    assert type(back) is FieldRecord and not back.text_built and not rec.text_built
    assert back.data == rec.data == displacement_json(10**18, field)
    assert back.field.micro.tolist() == field.micro.tolist()
    again = pickle.loads(pickle.dumps(back))  # a built text goes with it, and the numbers in µm
    assert again.text_built and again.data == rec.data and back.wire()[0] == "um"
    with pytest.raises(ValueError, match="one of them"):
        FieldRecord("pad", 0, 1)


def test_the_plane_numbers_it_and_its_binary_form_carries_that_seq():
    plane = EventPlane()
    plane.add_stream("pad", record=False)
    sub = plane.subscribe("pad", (KIND_EVENT, SKIN_DISPLACEMENT))
    rec = FieldRecord("pad", 0, 5, FieldArrays.of([1], [[0.5, 0, 0]]))
    plane.put(rec)
    assert sub.pending and struct.unpack_from("<4sIQq", rec.binary())[2] == rec.seq > 0
    assert rec.sse().startswith(f"id: {rec.seq}\n".encode())
