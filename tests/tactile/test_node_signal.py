"""A device whose node vectors are no displacement (``NodeSignal``): ε in its unit, no force it cannot
give, a force it measures summed, no collision from a speed that is not in mm/s; and its TD, and the
raw vector signals' encoding."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from wott_hub.errors import DriverError, InvalidInput
from wott_hub.examples import example_device
from wott_hub.runtime.payloads import contacts_json
from wott_hub.runtime.raw import encode_sample
from wott_hub.tactile import FrameProcessor, TactileFrame
from wott_hub.tactile.device import NodeSignal
from wott_hub.tactile.processing import processing_params
from wott_hub.tactile.raw import RawSample, RawSignal
from wott_hub.td.builder import build_tactile_td
from wott_hub.td.validate import validate_payload, validate_td

PAD = example_device("flat")


def pressed(signal: str, amount: float) -> tuple[FrameProcessor, list]:
    """Two frames: at rest, then a patch of nine nodes changed by ``amount`` along -z."""
    desc = replace(PAD, node_signal=NodeSignal(signal), epsilon_mm=amount / 10)
    proc = FrameProcessor(desc.mesh, processing_params(desc))
    centre = int(np.argmin(np.linalg.norm(desc.mesh.nodes - desc.mesh.nodes.mean(axis=0), axis=1)))
    near = np.argsort(np.linalg.norm(desc.mesh.nodes - desc.mesh.nodes[centre], axis=1))[:9]
    d = np.zeros((desc.mesh.n_nodes, 3))
    d[near, 2] = -amount
    return proc, [proc.process(TactileFrame.rest(desc.mesh.n_nodes, 0)), proc.process(TactileFrame(1_000, d))]


def test_a_signal_that_gives_no_force_reports_contacts_without_forces():
    _, (_, res) = pressed("magneticField", 400.0)
    assert len(res.contacts) == 1 and not res.forces
    info = res.contact_information()
    assert info["numOfContacts"] == 1 and info["contactForces"] == []
    assert json.loads(contacts_json(res)) == info  # the pipeline writes the same text
    assert res.actions == ["touch"]  # a field change this fast would be a "collision" if it were mm/s


def test_a_measured_force_is_summed_over_the_contact():
    _, (_, res) = pressed("force", 0.5)
    (contact,) = res.contacts
    assert res.forces and contact.force[2] == pytest.approx(-4.5)  # nine taxels of 0.5 N


def test_epsilon_and_the_below_threshold_note_are_in_the_signals_unit():
    desc = replace(PAD, node_signal=NodeSignal("taxelSignal"), epsilon_mm=12.0)
    p = processing_params(desc)
    assert (p.epsilon_mm, p.unit, p.force_model) == (12.0, "count", "none")
    proc = FrameProcessor(desc.mesh, replace(p, below_threshold_s=0.01))
    d = np.zeros((desc.mesh.n_nodes, 3))
    d[desc.mesh.free_indices[0], 2] = -6.0
    for t in range(4):
        proc.process(TactileFrame(t * 10_000_000, d))
    assert proc.below_note.startswith("below threshold: changed 3-12 count (epsilon 12 count)")
    with pytest.raises(ValueError, match="node signal must be one of"):
        NodeSignal("pressure")


@pytest.mark.parametrize(("signal", "unit"), [("magneticField", "uT"), ("taxelSignal", "count"),
                                              ("force", "N"), ("displacement", "mm")])
def test_the_td_says_what_the_nodes_measure_and_validates(signal, unit):
    td = build_tactile_td(replace(PAD, node_signal=NodeSignal(signal)))
    assert validate_td(td) == []
    node = td["events"]["skinDeformedDetection"]["data"]["properties"]["arrayOfDeformedNodes"]["items"]
    assert node["properties"]["deformedNodeIntensity"]["unit"] == unit
    assert ("skinDisplacement" in td["events"]) == (signal == "displacement")
    assert td.get("tac:nodeSignal") == (None if signal == "displacement" else signal)
    value = {"numOfContacts": 1, "contactLocations": [{"x": 1.0, "y": 2.0, "z": 0.0}], "contactForces": []}
    assert validate_payload(td, "property", "contactInformation", value) == []


def test_vector_signals_are_served_as_their_property_and_checked():
    raw = (RawSignal("raw", "vectors", (5, 3), unit="uT", term="magneticField"),
           RawSignal("change", "vectors", (5, 3), unit="uT", term="magneticField"))
    td = build_tactile_td(PAD, raw=raw)
    assert validate_td(td) == []
    prop = td["properties"]["magneticField"]
    assert prop["@type"] == "tac:MagneticField"
    assert prop["uriVariables"]["signal"]["enum"] == ["raw", "change"]
    sample = RawSample(7, np.arange(15.0).reshape(5, 3))
    value = json.loads(encode_sample(raw[1], sample, "json"))
    assert value == {"timeStamp": 7, "signal": "change", "numOfNodes": 5,
                     "vectors": [{"x": 3.0 * i, "y": 3.0 * i + 1, "z": 3.0 * i + 2} for i in range(5)]}
    assert validate_payload(td, "property", "magneticField", value) == []
    with pytest.raises(DriverError, match="is not a finite N x 3 array"):
        encode_sample(raw[0], RawSample(7, np.zeros((5, 2))), "json", "skin")
    with pytest.raises(InvalidInput, match="vectors and only vectors name their property"):
        RawSignal("raw", "vectors", (5, 3))
