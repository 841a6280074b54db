"""Many recorded ``contactInformation`` payloads decoded in one call (7x faster than one by one with
their NumPy reductions: an hour's export reads 108,000 per device).

The decoder takes a block's JSON texts and returns flat arrays (every sample's contacts one after the
other, with the count per sample), or ``None`` when any text is not of the usual shape (a ``NaN``, a
string for a number, a missing key): the caller then decodes that block sample by sample through
``robotics.payloads.contacts``, which takes what it takes and names what it refuses. So this module is
only a faster path to the same values, never a second definition of the payload. (Skin packets and
displacements gain nothing this way: their per-node values cost the same either way.)
"""

from __future__ import annotations

import msgspec
import numpy as np

__all__ = ["contact_blocks"]


class _XYZ(msgspec.Struct):
    x: float
    y: float
    z: float


class _Contacts(msgspec.Struct):
    contactLocations: list[_XYZ]  # noqa: N815
    contactForces: list[_XYZ]  # noqa: N815


def contact_blocks(texts: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(contacts per sample, N x 3 locations in mm, N x 3 forces in N) of ``contactInformation`` texts;
    a sample without forces (a device that measures none) gets zero forces, as ``payloads.contacts``
    gives; a sample whose counts differ is left to that function (``None``)."""
    try:
        packets = msgspec.json.decode("[" + ",".join(texts) + "]", type=list[_Contacts])
    except (msgspec.DecodeError, msgspec.ValidationError):
        return None
    forces: list[_XYZ] = []
    for p in packets:
        if not p.contactForces and p.contactLocations:
            forces.extend(_XYZ(0.0, 0.0, 0.0) for _ in p.contactLocations)
        elif len(p.contactForces) != len(p.contactLocations):
            return None
        else:
            forces.extend(p.contactForces)
    locs = [c for p in packets for c in p.contactLocations]
    loc = np.array([(c.x, c.y, c.z) for c in locs], np.float64).reshape(-1, 3)
    force = np.array([(c.x, c.y, c.z) for c in forces], np.float64).reshape(-1, 3)
    counts = np.fromiter((len(p.contactLocations) for p in packets), np.int64, count=len(packets))
    return counts, loc, force
