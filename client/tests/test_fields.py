"""The client's NumPy end to end (issue 29): displacement fields from the binary form (or SSE), raw
images and pressure grids as arrays, history ranges as arrays resumed after a record, actions and
property observation, sync and async, against live hubs."""

from __future__ import annotations

import asyncio
import copy
import struct
from contextlib import aclosing

import httpx
import numpy as np
import pytest
from wott_client import (
    AsyncClient,
    Client,
    ClientError,
    Displacement,
    Frame,
    InvalidTD,
    PacketParser,
    TransportError,
)

from wott_hub.events.fields import FieldArrays, FieldRecord

NORM_BOUND_MM = (3**0.5 / 2 + 0.5) / 1000 + 1e-6  # both rounded to 1 µm, then float32


def _td_url(hub, device: str) -> str:
    return hub.url + httpx.get(hub.url + "/wot").json()[device]


def test_the_packet_parser_cuts_a_stream_wherever_its_chunks_end():
    rng = np.random.default_rng(2)
    recs = [FieldRecord("t", k + 1, 10**18 + k, FieldArrays.of(rng.choice(99, n, replace=False),
                                                                rng.normal(0, 1, (n, 3))))
            for k, n in enumerate([0, 1, 20, 3, 57])]
    blob = b"".join(r.binary() for r in recs)
    for step in (1, 7, 24, 1000):
        parser, got = PacketParser("t"), []
        for i in range(0, len(blob), step):
            got += parser.feed(blob[i:i + step])
        assert [p.event_id for p in got] == ["1", "2", "3", "4", "5"]
        for p, r in zip(got, recs, strict=True):
            assert p.timestamp_ns == r.t_ns and p.ids.tolist() == r.field.ids.tolist()
            np.testing.assert_array_equal(p.vectors, r.field.mm().astype(np.float32))
    with pytest.raises(ClientError, match="magic"):
        PacketParser("t").feed(b"XXXX" + bytes(40))


def test_displacements_from_the_binary_form_have_the_norms_of_the_frames_intensities(hub, run):
    async def scenario():
        async with AsyncClient() as c:
            thing = await c.async_thing(_td_url(hub, "pad"))
            mesh = await thing.async_mesh()
            fields: list[Displacement] = []
            frames: dict[int, Frame] = {}

            async def vectors():
                async with aclosing(thing.async_displacements()) as it:
                    async for d in it:
                        fields.append(d)
                        if len(fields) >= 40:
                            return

            async def intensities():
                async with aclosing(thing.async_frames(contacts=False, actions=False)) as it:
                    async for f in it:
                        frames[f.timestamp_ns] = f
                        if len(frames) >= 80:
                            return

            await asyncio.gather(vectors(), intensities())
            return thing, mesh, fields, frames

    thing, mesh, fields, frames = run(scenario())
    assert thing._displacement_form()[1] is True  # the binary form was taken
    matched = 0
    for d in fields:
        assert d.vectors.dtype == np.float32 and d.vectors.shape == (len(d.ids), 3)
        f = frames.get(d.timestamp_ns)
        if f is not None and len(d.ids):
            rows = mesh.index_of(d.ids)
            assert np.abs(d.norms() - f.intensity[rows]).max() <= NORM_BOUND_MM
            assert d.dense(len(mesh), rows).shape == (len(mesh), 3)
            matched += 1
    assert matched >= 10


def test_without_a_binary_form_the_sse_json_gives_the_same_arrays(hub, run):
    """The same packets (by event id) read from the JSON form and from the binary form at once:
    the same node ids, the same float32 vectors, the same time stamps."""
    url = _td_url(hub, "pad")
    td = httpx.get(url).json()
    json_only = copy.deepcopy(td)
    ev = json_only["events"]["skinDisplacement"]
    ev["forms"] = [f for f in ev["forms"] if f["contentType"] == "application/json"]

    async def scenario():
        async with AsyncClient() as c:
            from_json, from_binary = c.thing_from_td(json_only, url), c.thing_from_td(td, url)
            got: dict[bool, dict[str, Displacement]] = {False: {}, True: {}}

            async def read(thing, binary: bool) -> None:
                async with aclosing(thing.async_displacements()) as it:
                    async for d in it:
                        got[binary][d.event_id] = d
                        if len(got[False].keys() & got[True].keys()) >= 5:
                            return

            await asyncio.wait_for(asyncio.gather(read(from_json, False), read(from_binary, True)), 60)
            return from_json, from_binary, got

    from_json, from_binary, got = run(scenario())
    assert from_json._displacement_form()[1] is False and from_binary._displacement_form()[1] is True
    common = sorted(got[False].keys() & got[True].keys(), key=int)
    assert len(common) >= 5
    for event_id in common:
        j, b = got[False][event_id], got[True][event_id]
        assert j.vectors.dtype == b.vectors.dtype == np.float32 and j.timestamp_ns == b.timestamp_ns
        assert j.ids.tolist() == b.ids.tolist()
        np.testing.assert_array_equal(j.vectors, b.vectors)


def test_raw_frames_as_arrays_and_bad_input_named(recorded, eventually):
    with Client() as c:
        cam, grid, pad = (c.thing(_td_url(recorded, d)) for d in ("cam", "grid", "pad"))
        assert cam.cameras == ["camera"] and grid.cameras == []

        first = eventually(lambda: _or_none(cam.image), timeout=60, what="the camera's first image")[0]
        assert first.shape == (480, 640, 1) and first.dtype == np.uint8
        assert cam.frame().shape == (480, 640, 1)  # digit-interface's get_frame: the latest image
        with pytest.raises(TransportError, match="camera"):
            cam.image("left")
        grid_frame = eventually(lambda: _or_none(grid.pressure), timeout=30, what="the grid")[0]
        assert grid_frame.shape == (16, 16) and grid_frame.dtype == np.float32
        assert grid.frame().shape == (16, 16)
        with pytest.raises(ClientError, match="no raw frame"):
            pad.frame()


def _or_none(fn):
    """``(fn(),)``, or None while the device has no frame yet (503)."""
    try:
        return (fn(),)
    except TransportError as e:
        if "503" in str(e):
            return None
        raise


def test_actions_and_observed_properties(recorded):
    with Client() as c:
        pad = c.thing(_td_url(recorded, "pad"))
        done = pad.tare()
        assert done["invokedAction"] == "tare" and done["outcome"] == "ok"
        assert pad.invoke("restart")["invokedAction"] == "restart"
        with pytest.raises(InvalidTD, match="fly"):
            pad.invoke("fly")
        for n, value in enumerate(pad.observe("contactInformation")):
            assert "numOfContacts" in value
            if n == 1:
                break


def test_history_ranges_are_arrays_and_resume_after_a_record(recorded, eventually):
    hub_url = f"{recorded.url}/wot/hub"
    with Client() as c:
        history = c.history(hub_url)
        whole = eventually(lambda: r if len(r := history.range("pad", limit=60)) == 60 else None,
                           timeout=30, what="60 recorded skinDisplacement packets")
        assert whole.seq.dtype == np.int64 and whole.values.shape == (whole.offsets[-1], 3)
        head = history.range("pad", limit=25)
        tail = history.range("pad", after=head.last_seq, limit=35)
        assert np.array_equal(np.concatenate([head.seq, tail.seq]), whole.seq)  # none lost, none twice
        assert np.array_equal(np.concatenate([head.values, tail.values]), whole.values)
        mesh = c.thing(_td_url(recorded, "pad")).mesh()
        dense = whole.dense(len(mesh), mesh.index_of(whole.ids))
        assert dense.shape == (60, len(mesh), 3) and np.abs(dense).max() > 0.1
        inten = history.range("pad", "skinDeformedDetection", limit=60)
        by_time = dict(zip(inten.t_ns.tolist(), range(len(inten)), strict=True))
        for k in range(len(whole)):
            if int(whole.t_ns[k]) in by_time and whole.offsets[k + 1] > whole.offsets[k]:
                ids, vec = whole.packet(k)
                ids2, val = inten.packet(by_time[int(whole.t_ns[k])])
                assert ids.tolist() == ids2.tolist()
                assert np.abs(np.linalg.norm(vec, axis=1) - val).max() <= NORM_BOUND_MM
        with pytest.raises(ClientError, match="actionDetection"):
            history.range("pad", "actionDetection")


def test_the_binary_stream_survives_a_dropped_connection(hub, proxy, run):
    """Through a relay cut once: the packets go on after the last seq received, none lost or twice."""
    url = _td_url(hub, "pad")
    host, port = httpx.URL(hub.url).host, httpx.URL(hub.url).port

    async def scenario():
        p = await proxy(host, port).start()
        try:
            td = httpx.get(url).json()
            text = json_swap(td, f"{host}:{port}", f"127.0.0.1:{p.port}")
            async with AsyncClient() as c:
                thing = c.thing_from_td(text)
                seqs = []
                async with aclosing(thing.async_displacement_batches()) as it:
                    async for batch in it:
                        seqs += [int(d.event_id) for d in batch]
                        if len(seqs) >= 10 and p.drops == 0:
                            p.drop(0.3)
                        if len(seqs) >= 40:
                            break
            return seqs, p.drops
        finally:
            await p.stop()

    seqs, drops = run(scenario(), 60)
    assert drops == 1 and seqs == sorted(set(seqs))


def json_swap(td: dict, old: str, new: str) -> dict:
    import json

    return json.loads(json.dumps(td).replace(old, new))


def test_packets_carry_their_seq_as_documented(hub):
    url = _td_url(hub, "pad")
    with httpx.stream("GET", f"{url}/events/skinDisplacement/binary", timeout=20) as r:
        blob = b""
        for chunk in r.iter_raw():
            blob += chunk
            if len(blob) >= 24:
                break
    magic, n, seq, ts = struct.unpack_from("<4sIQq", blob)
    assert magic == b"WTD1" and seq > 0 and ts > 1_700_000_000 * 10**9
