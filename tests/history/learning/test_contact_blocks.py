"""The block decoder of ``contactInformation`` gives what the sample-by-sample path gives, and hands
back to it what it does not take (issue 46: the export's speed must not change a value)."""

from __future__ import annotations

import json

import numpy as np

from wott_hub.events.record import KIND_PROPERTY, Record
from wott_hub.history.learning.features import ContactsSource, Source
from wott_hub.history.learning.packets import contact_blocks


def _text(locs: list[tuple[float, float, float]], forces: list[tuple[float, float, float]]) -> str:
    xyz = [{"x": x, "y": y, "z": z} for x, y, z in locs]
    return json.dumps({
        "numOfContacts": len(locs),
        "contactLocations": xyz,
        "contactForces": [{"x": x, "y": y, "z": z} for x, y, z in forces],
    })


def _records(texts: list[str]) -> list[Record]:
    return [Record("pad", i, KIND_PROPERTY, "contactInformation", i, t) for i, t in enumerate(texts)]


def _one_by_one(source: ContactsSource, recs: list[Record]) -> list[np.ndarray]:
    return Source.decode_many(source, recs)


def test_a_block_decodes_as_its_samples_do() -> None:
    rng = np.random.default_rng(5)
    texts = [_text([], [])]  # untouched
    texts.append(_text([(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)], []))  # a skin that measures no force
    texts.append(_text([(1.0, 2.0, 3.0)], [(0.0, 0.0, 0.0)]))  # force measured as zero: unweighted
    for _ in range(200):
        n = int(rng.integers(0, 4))
        locs = [tuple(v) for v in rng.normal(0, 10, (n, 3)).round(3).tolist()]
        forces = [tuple(v) for v in rng.normal(0, 1, (n, 3)).round(3).tolist()]
        texts.append(_text(locs, forces))  # type: ignore[arg-type]
    source = ContactsSource("pad")
    recs = _records(texts)
    assert contact_blocks(texts) is not None
    fast, slow = source.decode_many(recs), _one_by_one(source, recs)
    for a, b in zip(fast, slow, strict=True):
        assert a.shape == b.shape and a.dtype == b.dtype
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6)


def test_what_the_block_decoder_does_not_take_goes_sample_by_sample() -> None:
    odd = '{"contactLocations": [{"x": NaN, "y": 0, "z": 0}], "contactForces": []}'  # Python's JSON
    texts = [_text([(1.0, 2.0, 3.0)], [(0.0, 0.0, -1.0)]), odd]
    assert contact_blocks(texts) is None
    source = ContactsSource("pad")
    count, _centroid, force = source.decode_many(_records(texts))
    assert count[:, 0].tolist() == [1, 1]
    assert force[0].tolist() == [0.0, 0.0, -1.0]
