"""The hub's hand-written record texts are exactly ``encode`` of the payloads (runtime/payloads.py)."""

from __future__ import annotations

import numpy as np
import pytest

from wott_hub.events.record import encode
from wott_hub.examples import example_device
from wott_hub.runtime.payloads import contacts_json, skin_deformed_json
from wott_hub.tactile import FrameProcessor, TactileFrame
from wott_hub.tactile.indentation import Indenter, indent


@pytest.mark.parametrize("shape", ["flat", "barrel"])
def test_texts_equal_encode_of_the_payloads_on_random_multi_contact_frames(shape):
    desc = example_device(shape)
    mesh = desc.mesh
    free = mesh.free_indices
    proc = FrameProcessor(desc.mesh)
    rng = np.random.default_rng(7)
    seen_contacts = set()
    for t in range(1, 200):
        if t % 7 == 0:  # rest frames: releases and empty contact lists
            d = np.zeros_like(mesh.nodes)
        else:
            presses = [Indenter(mesh.nodes[rng.choice(free)], float(rng.uniform(0.05, 40.0)),
                                float(rng.uniform(1.0, 9.0)), rng.normal(0, 0.5, 3))
                       for _ in range(int(rng.integers(1, 5)))]
            d = indent(mesh, presses) * float(rng.choice([1e-3, 1.0, 3.7]))
        res = proc.process(TactileFrame(t, d))
        seen_contacts.add(len(res.contacts))
        if res.packet_due:
            assert skin_deformed_json(res) == encode(res.skin_deformed_detection())
        assert contacts_json(res) == encode(res.contact_information())
    assert {0, 1}.issubset(seen_contacts) and max(seen_contacts) >= 2


def test_a_packet_of_no_nodes_and_one_of_a_node_id_not_seen_before_equal_encode_too():
    from wott_hub.tactile import FrameResult

    # node heads are made as ids come, and not kept past NODE_HEADS_MAX (a 2**32 id is written as is)
    for ids, values in (([], []), ([5], [0.25]), ([3, 2_000], [1e-05, 12.5]), ([7, 2**32 + 9], [0.5, 2.0])):
        res = FrameResult(9, np.array(ids, dtype=np.int64), np.array(values), False, [], [], True)
        assert skin_deformed_json(res) == encode(res.skin_deformed_detection())


def test_a_contact_whose_numbers_are_not_finite_is_refused_as_encode_refuses_it():
    desc = example_device("flat")
    proc = FrameProcessor(desc.mesh)
    d = indent(desc.mesh, [Indenter(desc.mesh.nodes[desc.mesh.free_indices[100]], 1.0, 4.0)])
    res = proc.process(TactileFrame(1, d))
    res.contacts[0].force[2] = np.inf  # what an overflowing force model would produce
    with pytest.raises(ValueError):
        encode(res.contact_information())
    with pytest.raises(ValueError, match="not JSON compliant"):
        contacts_json(res)
