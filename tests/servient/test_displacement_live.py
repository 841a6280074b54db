"""``skinDisplacement`` on a real hub (issue 29): SSE, the WebSocket JSON-RPC, the binary HTTP stream and
the binary WebSocket all give vectors whose norms equal the same frame's intensities and, for the
ground-truth scene driver, the scene's own displacement within the packet quantisation; the binary
stream resumes after a packet; recorded and replayed."""

from __future__ import annotations

import asyncio
import json
import struct
from dataclasses import replace

import httpx
import numpy as np
import pytest
import tornado.httpclient
import tornado.websocket

from wott_hub.config import HubConfig
from wott_hub.drivers.scene import SceneDriver
from wott_hub.examples import example_device
from wott_hub.hub import Hub
from wott_hub.network import DiscoveryConfig
from wott_hub.sim.scene import Scene

QUANTUM_MM = 0.5e-3  # a component rounded to 1 µm
NORM_BOUND_MM = (3**0.5 / 2 + 0.5) / 1000  # |norm(rounded vector) - rounded norm|
FLOAT32 = 1e-6  # the binary form's float32 of the µm values (mm < 10: 7 digits)


class TruthScene(SceneDriver):
    """The scene driver, keeping each frame's displacement by its time (the test's ground truth)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.truth: dict[int, np.ndarray] = {}

    async def frames(self):
        async for frame in super().frames():
            self.truth[frame.t_ns] = frame.displacement
            yield frame


def _slide_scene() -> tuple:
    """A flat pad pressed and slid (shear), then at rest, looping: vectors with all three components."""
    desc = replace(example_device("flat"), id="pad", title="pad")
    free = desc.mesh.free_indices
    a, b = (desc.mesh.nodes[free[len(free) // 2 + k]].tolist() for k in (-40, 40))
    scene = Scene.from_dict({"scene": {"name": "slide", "loop": True}, "step": [
        {"kind": "slide", "at": a, "to": b, "start_s": 0.05, "duration_s": 0.5, "depth_mm": 1.5,
         "radius_mm": 5.0, "ramp_s": 0.05, "shear_mm": 0.6}]})
    return desc, scene


async def _hub(tmp_path) -> tuple[Hub, TruthScene]:
    hub = Hub(HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), history_batch_ms=20,
                        discovery=DiscoveryConfig.off()))
    await hub.start()
    desc, scene = _slide_scene()
    driver = TruthScene(desc, scene, 60.0)
    await hub.add_driver(driver, family="scene")
    return hub, driver


async def _sse(url: str, n: int, out: list, headers: dict | None = None) -> None:
    from httpx_sse import aconnect_sse

    async with httpx.AsyncClient(timeout=20) as c, aconnect_sse(c, "GET", url, headers=headers or {}) as es:
        async for ev in es.aiter_sse():
            out.append((int(ev.id), json.loads(ev.data)))
            if len(out) >= n:
                return


def _packets(blob: bytes) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """(seq, timeStamp, ids, vectors) of each packet of a binary stream's bytes."""
    out, at = [], 0
    while len(blob) - at >= 24:
        magic, n, seq, ts = struct.unpack_from("<4sIQq", blob, at)
        assert magic == b"WTD1"
        if len(blob) - at < 24 + 16 * n:
            break
        ids = np.frombuffer(blob, "<u4", n, at + 24)
        vec = np.frombuffer(blob, "<f4", 3 * n, at + 24 + 4 * n).reshape(n, 3)
        out.append((seq, ts, ids, vec))
        at += 24 + 16 * n
    return out


async def _binary_http(url: str, n: int, out: list, after: int | None = None) -> None:
    headers = {} if after is None else {"Last-Event-ID": str(after)}
    async with httpx.AsyncClient(timeout=20) as c, c.stream("GET", url, headers=headers) as r:
        assert r.status_code == 200 and r.headers["content-type"] == "application/vnd.wott.skin-displacement"
        blob = b""
        async for chunk in r.aiter_raw():
            blob += chunk
            if len(_packets(blob)) >= n:
                out += _packets(blob)[:n]
                return


async def _binary_ws(url: str, n: int, out: list) -> None:
    conn = await tornado.websocket.websocket_connect(url)
    try:
        while len(out) < n:
            msg = await asyncio.wait_for(conn.read_message(), 20)
            assert isinstance(msg, bytes)
            got = _packets(msg)
            assert len(got) == 1  # one message per packet
            out += got
    finally:
        conn.close()


async def _jsonrpc_ws(url: str, n: int, out: list) -> None:
    conn = await tornado.websocket.websocket_connect(url)
    try:
        conn.write_message(json.dumps({"jsonrpc": "2.0", "method": "on_event",
                                       "params": {"name": "skinDisplacement"}, "id": 1}))
        while len(out) < n:
            msg = json.loads(await asyncio.wait_for(conn.read_message(), 20))
            if "subscription" in msg and msg.get("name") == "skinDisplacement":
                out.append(msg["data"])
    finally:
        conn.close()


def _vectors(packet: dict) -> tuple[list[int], np.ndarray]:
    nodes = packet["arrayOfDisplacedNodes"]
    return ([d["nodeID"] for d in nodes],
            np.array([[d["displacement"][a] for a in "xyz"] for d in nodes]).reshape(-1, 3))


def test_every_binding_gives_the_vectors_of_the_frames_intensities_and_the_scenes_truth(tmp_path, run):
    async def scenario() -> None:
        hub, driver = await _hub(tmp_path)
        try:
            async with httpx.AsyncClient() as c:
                td = (await c.get(hub.td_url("pad"))).json()
            forms = td["events"]["skinDisplacement"]["forms"]
            binary = [f for f in forms if f["contentType"] == "application/vnd.wott.skin-displacement"]
            http_form = next(f for f in binary if f["href"].startswith("http"))
            ws_form = next(f for f in binary if f["href"].startswith("ws"))
            assert http_form["subprotocol"] == "stream" and http_form["htv:methodName"] == "GET"
            jsonrpc = next(f for f in forms
                           if f["href"].startswith("ws") and f["contentType"] == "application/json")
            intensities, sse, rpc, bin_http, bin_ws = [], [], [], [], []
            await asyncio.gather(
                _sse(f"{hub.td_url('pad')}/events/skinDeformedDetection", 120, intensities),
                _sse(f"{hub.td_url('pad')}/events/skinDisplacement", 60, sse),
                _jsonrpc_ws(jsonrpc["href"], 60, rpc),
                _binary_http(http_form["href"], 60, bin_http),
                _binary_ws(ws_form["href"], 60, bin_ws))
        finally:
            await hub.stop()
        by_time = {p["timeStamp"]: {n["deformedNodeID"]: n["deformedNodeIntensity"]
                                    for n in p["arrayOfDeformedNodes"]} for _, p in intensities}
        checked = sheared = 0
        texts = [("sse", p) for _, p in sse] + [("ws", p) for p in rpc]
        arrays = [(ts, ids.tolist(), vec.astype(np.float64)) for _, ts, ids, vec in bin_http + bin_ws]
        for ts, ids, vec in [(p["timeStamp"], *_vectors(p)) for _, p in texts] + arrays:
            truth = driver.truth[ts][ids]
            np.testing.assert_allclose(vec, truth, atol=QUANTUM_MM + FLOAT32)  # the scene's own vectors
            if ts in by_time:  # the same frame's intensities: the same nodes, the norms
                assert list(by_time[ts]) == ids
                norms = np.linalg.norm(vec, axis=1)
                assert np.abs(norms - np.array(list(by_time[ts].values()))).max() <= NORM_BOUND_MM + FLOAT32
                checked += 1
            sheared += bool(np.abs(vec[:, :2]).max(initial=0) > 0.05)  # along the pad: shear left the hub
        assert checked >= 40 and sheared >= 10
        assert len({ts for ts, _, _ in arrays}) >= 30

    run(scenario(), 120)


def test_the_binary_stream_resumes_after_a_packet_and_a_replay_serves_the_recorded_vectors(tmp_path, run):
    async def scenario() -> None:
        hub, driver = await _hub(tmp_path)
        try:
            url = f"{hub.td_url('pad')}/events/skinDisplacement/binary"
            first: list = []
            await _binary_http(url, 20, first)
            seqs = [p[0] for p in first]
            resumed: list = []
            await _binary_http(url, 10, resumed, after=seqs[4])
            assert [p[0] for p in resumed[:15]][:10] == seqs[5:15]  # nothing lost, nothing twice
            for a, b in zip(first[5:15], resumed, strict=False):
                assert a[1] == b[1] and a[2].tolist() == b[2].tolist() and np.array_equal(a[3], b[3])
            # recorded: a replay of the device serves skinDisplacement (SSE; binary, from its text)
            assert await asyncio.to_thread(hub.flush_history, 10)
            rt = await hub.add_replay("pad", speed=4.0, loop=True)
            hub.start_replay(rt)
            replay_url = hub.td_url(rt.id)
            async with httpx.AsyncClient() as c:
                td = (await c.get(replay_url)).json()
            assert "skinDisplacement" in td["events"] and "rawImage" not in td["properties"]
            got: list = []
            await _sse(f"{replay_url}/events/skinDisplacement", 10, got)
            replayed_bin: list = []
            await _binary_http(f"{replay_url}/events/skinDisplacement/binary", 10, replayed_bin)
            # the recorded packets, as the scene made them: the replay keeps their time stamps
            replayed = [(p["timeStamp"], *_vectors(p)) for _, p in got]
            replayed += [(ts, ids.tolist(), vec.astype(np.float64)) for _, ts, ids, vec in replayed_bin]
            for ts, ids, vec in replayed:
                np.testing.assert_allclose(vec, driver.truth[ts][ids], atol=QUANTUM_MM + FLOAT32)
            assert sum(len(ids) > 0 for _, ids, _ in replayed) >= 5
            assert all(seq > 0 for seq, *_ in replayed_bin)
        finally:
            await hub.stop()

    run(scenario(), 120)


def test_bad_input_on_the_binary_forms_is_a_problem_naming_it(tmp_path, run):
    async def scenario() -> None:
        hub, _ = await _hub(tmp_path)
        try:
            base = hub.td_url("pad")
            async with httpx.AsyncClient(timeout=10) as c:
                r = await c.get(f"{base}/events/skinDisplacement/binary", headers={"Last-Event-ID": "x"})
                assert r.status_code == 400 and "Last-Event-ID" in r.json()["detail"]
                r = await c.get(f"{base}/events/actionDetection/binary")  # no binary form
                assert r.status_code == 404 and "actionDetection" in r.json()["detail"]
                assert r.headers["content-type"] == "application/problem+json"
                r = await c.get(f"{hub.td_url('nothing')}/events/skinDisplacement/binary")
                assert r.status_code == 404 and "nothing" in r.json()["detail"]
            with pytest.raises(tornado.httpclient.HTTPClientError, match="404"):
                await tornado.websocket.websocket_connect(
                    f"{base.replace('http', 'ws', 1)}/events/actionDetection/binary/ws")
        finally:
            await hub.stop()

    run(scenario(), 60)
