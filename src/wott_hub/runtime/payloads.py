"""The JSON texts of a frame's records, written straight from the processor's arrays (and the
numbers of its ``skinDisplacement`` packet, whose forms ``events.fields`` writes on demand).

Contract: each function returns exactly ``events.record.encode`` of the payload the
``FrameResult`` describes (``skin_deformed_detection()``, ``contact_information()``), byte for
byte: clients, history and the codec's packed form all rely on that one text
(tests/hub/test_payloads.py compares them on random frames). They exist because every
frame of every device pays for them on the hub's event loop: building a dict per node or
per contact first and encoding it costs 2-4x more (contacts: 11.6 against 6 µs; docs/hub.md,
"Where the loop's time goes").
"""

from __future__ import annotations

import numpy as np

from wott_hub.tactile import FrameResult

__all__ = ["contacts_json", "displacement_rows", "skin_deformed_json"]


_NODE_HEADS: list[str] = []
"""Node ``i``'s ``{"deformedNodeID":<i>,"deformedNodeIntensity":``, made once per id, not per frame."""

NODE_HEADS_MAX = 1 << 16
"""Ids up to this have their head kept (a mesh has a few thousand nodes); larger ones (only ever
seen in tests) are written per packet."""


def _head(i: int) -> str:
    return f'{{"deformedNodeID":{i},"deformedNodeIntensity":'


class _Reprs(dict[float, str]):
    """``repr`` of each intensity seen, kept: intensities are rounded (to 1 µm by default), so a
    device's packets repeat a few thousand values, and a lookup costs a fifth of a float's repr
    (the skin packet's text 8.0 against 4.5 µs for the hub benchmark's press frame). Keyed by value:
    -0.0 would find 0.0's text, but an intensity is a norm (or a release's zero), never -0.0."""

    def __missing__(self, value: float) -> str:
        if len(self) >= REPRS_MAX:  # a processor that does not round: keep the memory bounded
            self.clear()
        text = self[value] = repr(value)
        return text


REPRS_MAX = 1 << 16
_REPRS = _Reprs()


def skin_deformed_json(res: FrameResult) -> str:
    """``encode(res.skin_deformed_detection())`` (Python's float repr is what ``json`` writes)."""
    ids = res.deformed_nodes.tolist()
    if not ids:
        return f'{{"timeStamp":{res.t_ns},"numOfDeformedNodes":0,"arrayOfDeformedNodes":[]}}'
    heads, top = _NODE_HEADS, max(ids)
    if len(heads) <= top < NODE_HEADS_MAX:
        heads += map(_head, range(len(heads), top + 1))
    reprs, values = _REPRS, res.intensity.tolist()
    if top < len(heads):
        nodes = "},".join([heads[i] + reprs[v] for i, v in zip(ids, values, strict=True)])
    else:
        nodes = "},".join([_head(i) + reprs[v] for i, v in zip(ids, values, strict=True)])
    return f'{{"timeStamp":{res.t_ns},"numOfDeformedNodes":{len(ids)},"arrayOfDeformedNodes":[{nodes}}}]}}'


def _xyz(values: list[float]) -> str:
    x, y, z = values
    return f'{{"x":{round(x, 4)!r},"y":{round(y, 4)!r},"z":{round(z, 4)!r}}}'


def contacts_json(res: FrameResult) -> str:
    """``encode(res.contact_information())``: rounded to 0.1 µm / 0.1 mN as that method rounds;
    ``contactIds`` while touched (issue 31); ``contactForces`` empty for a device whose node vectors give
    no force (``FrameResult.forces``)."""
    contacts = res.contacts
    where = ",".join([_xyz(c.location.tolist()) for c in contacts])
    force = ",".join([_xyz(c.force.tolist()) for c in contacts]) if res.forces else ""
    if "n" in where or "n" in force:  # "nan"/"inf": the only letters besides x, y, z there
        raise ValueError("Out of range float values are not JSON compliant")  # as encode() says
    ids = f',"contactIds":[{",".join([str(c.id) for c in contacts])}]' if contacts else ""
    if res.radii:  # a device that measures its contacts (tactile.measured)
        radii = ",".join([repr(round(c.radius, 4)) for c in contacts])
        ids = f',"contactRadii":[{radii}]{ids}'
    return f'{{"numOfContacts":{len(contacts)},"contactLocations":[{where}],"contactForces":[{force}]{ids}}}'


def displacement_rows(res: FrameResult, displacement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``skinDisplacement`` packet of a frame as the pipeline hands it over: the skin packet's nodes
    (``res.deformed_nodes``) and their rows of ``displacement`` (mm, a copy), all zero in the release
    packet (the skin at rest); ``events.fields.FieldArrays.of`` quantises them to µm when first
    needed. The norm of each quantised vector is the node's ``deformedNodeIntensity`` within the
    quantisation: both are rounded to 1 µm, the intensity from the exact norm, the vector per
    component (docs/tactile-td.md)."""
    ids = res.deformed_nodes
    if res.is_release:
        return ids, np.zeros((len(ids), 3))
    return ids, displacement[ids]
