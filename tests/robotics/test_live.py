"""The live Foxglove endpoint of a real hub, read by a client of the protocol (``fox_client``):
its channels and bytes equal the MCAP export's, it builds only what is subscribed, it sends the
mesh and frames on subscribe and always the latest scene, bad clients change nothing for good
ones, and its trust rule (loopback unless told) holds. Foxglove's own client library is driven in
tests/interop/test_foxglove.py."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from pathlib import Path

import pytest

from .fox_client import FoxClient
from .foxglove_proto import decode

WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")
SKIN = "/pad/events/skinDeformedDetection"


def _config(tmp_path, press_scene, *, history: bool = True, **foxglove):
    from wott_hub.config import HubConfig
    from wott_hub.robotics.config import FoxgloveConfig

    return HubConfig(http_port=0, ws_port=None, history=history, database=str(tmp_path / "hub.db"),
                     history_batch_ms=20, devices=(press_scene("pad"),),
                     foxglove=FoxgloveConfig(port=0, **foxglove))


async def _client(hub, wait_for) -> FoxClient:
    c = await FoxClient.connect(hub.describe()["foxglove"])
    await wait_for(lambda: SKIN in c.channels and "/tf" in c.channels, what="the channels advertised")
    return c


def _export(db: Path, devices: list[str]) -> tuple[dict, list]:
    """The MCAP export of the hub's history: channels by topic and (topic, log time, data) messages."""
    import io

    from mcap.reader import make_reader

    from wott_hub.history import HistoryReader, create_engine, database_url
    from wott_hub.history.mcap import export_mcap

    engine = create_engine(database_url(db))
    buf = io.BytesIO()
    export_mcap(HistoryReader(engine), buf, devices)
    engine.dispose()
    buf.seek(0)
    reader = make_reader(buf)
    channels, msgs = {}, []
    for schema, ch, m in reader.iter_messages(log_time_order=False):
        channels[ch.topic] = (ch.message_encoding, schema.name, schema.encoding, schema.data)
        msgs.append((ch.topic, m.log_time, m.data))
    return channels, msgs


def test_the_channels_schemas_and_bytes_equal_the_mcap_export(tmp_path, press_scene, run, wait_for):
    from wott_hub.hub import Hub

    topics = [SKIN, "/pad/properties/contactInformation", "/pad/log", "/pad/scene/deformation",
              "/pad/scene/contacts", "/pad/events/actionDetection"]

    async def main():
        async with Hub(_config(tmp_path, press_scene)) as hub:
            c = await _client(hub, wait_for)
            await c.subscribe(*topics)
            await wait_for(lambda: len(c.of("/pad/log")) >= 4 and len(c.of("/pad/scene/deformation")) >= 20,
                           timeout=30, what="actions and scenes at the client")
            await c.close()
            assert await asyncio.to_thread(hub.flush_history)
            return c

    c = run(main())
    channels, msgs = _export(tmp_path / "hub.db", ["pad"])
    for topic in topics:  # the same channel: encoding, schema name, schema encoding, schema bytes
        live = c.channels[topic]
        schema = live["schema"].encode() if live["schemaEncoding"] != "protobuf" else None
        enc, name, senc, data = channels[topic]
        assert (live["encoding"], live["schemaName"], live["schemaEncoding"]) == (enc, name, senc), topic
        if schema is not None:
            assert json.loads(schema) == json.loads(data), topic
        else:  # protobuf schemas travel base64-encoded in the protocol
            import base64

            assert base64.b64decode(live["schema"]) == data, topic
    exported: dict[tuple[str, int], list[bytes]] = {}
    for t, lt, d in msgs:
        exported.setdefault((t, lt), []).append(d)
    for topic in (SKIN, "/pad/properties/contactInformation", "/pad/log", "/pad/events/actionDetection"):
        got = c.of(topic)
        assert got, topic
        for t, payload in got:  # every record: the same bytes at the same log time
            assert payload in exported[(topic, t)], topic
    # scenes: throttled on each side by its own clock, so compared where both drew the same packet
    mine = {p for t, p in c.of("/pad/scene/deformation")}
    theirs = {d for t, lt, d in msgs if t == "/pad/scene/deformation"}
    assert len(mine & theirs) >= 3


def test_only_what_a_client_subscribes_to_is_built(tmp_path, press_scene, run, wait_for):
    from wott_hub.hub import Hub

    async def main():
        async with Hub(_config(tmp_path, press_scene, history=False)) as hub:
            live = hub._foxglove  # no public face: the endpoint's counters
            c = await _client(hub, wait_for)
            await asyncio.sleep(0.3)
            assert live.sent == 0 and not any(live.active.values())  # connected, nothing subscribed
            await c.subscribe(SKIN)
            await wait_for(lambda: len(c.of(SKIN)) >= 10, what="skin packets")
            assert {t for t, _, _ in c.messages} == {SKIN}
            assert not hub._plane.stream("hub").taps[-1].active  # the hub Thing's tap stays off
            await c.unsubscribe(SKIN)
            await wait_for(lambda: not any(live.active.values()), what="the tap off after unsubscribing")
            sent = live.sent
            await asyncio.sleep(0.3)
            assert live.sent == sent
            await c.close()

    run(main())


def test_each_message_leaves_the_hub_once_however_many_subscribe(tmp_path, press_scene, run, wait_for):
    """Issue 48, item 6: the fan-out to the viewers is the relay process's (``robotics/relay.py``); the hub
    encodes each message once and writes it once to the relay, so three subscribers of the skin packets
    cost the hub what one does: one message per record (the SDK copied it once per client, in the hub,
    holding the GIL)."""
    from wott_hub.events.record import KIND_EVENT
    from wott_hub.hub import Hub

    async def main():
        async with Hub(_config(tmp_path, press_scene, history=False)) as hub:
            live = hub._foxglove
            clients = [await _client(hub, wait_for) for _ in range(3)]
            for c in clients:
                await c.subscribe(SKIN)
            await wait_for(lambda: all(len(c.of(SKIN)) >= 5 for c in clients), what="skin packets at all 3")
            counts = hub._plane.stream("pad").counts
            name = SKIN.rpartition("/")[2]
            assert hub._plane.wants("pad", KIND_EVENT, name)
            records0, sent0 = counts[name], live.sent
            await wait_for(lambda: counts[name] - records0 >= 30, what="30 more skin packets")
            records, sent = counts[name] - records0, live.sent - sent0
            assert records - 2 <= sent <= records + 2, (records, sent)  # once each, not once per client
            await wait_for(lambda: live.health()["relaySent"] >= live.sent - 5, what="the relay's counters")
            assert live.health()["clients"] == 3 and live.health()["notSent"] == 0
            for c in clients:
                await c.close()

    run(main())


def _their_descriptor(pid: int, fd: int) -> int:
    """A duplicate, here, of process ``pid``'s descriptor ``fd`` (Linux's ``pidfd_getfd``; root or ptrace
    rights over it: CI runs as root)."""
    import ctypes
    import os

    libc = ctypes.CDLL(None, use_errno=True)
    pidfd = os.pidfd_open(pid)
    try:
        dup = libc.syscall(438, pidfd, fd, 0)  # SYS_pidfd_getfd
        assert dup >= 0, os.strerror(ctypes.get_errno())
        return int(dup)
    finally:
        os.close(pidfd)


def test_messages_are_not_held_by_nagle(tmp_path, press_scene, run, wait_for):
    """The SDK accepts clients without TCP_NODELAY; the relay turns it on through the listener
    (``robotics.nagle``): small messages would otherwise wait for the client's delayed ACK. The sockets
    are the relay process's (``robotics/relay.py``), none the hub's."""
    import socket

    from wott_hub.hub import Hub
    from wott_hub.robotics.nagle import ESTABLISHED, descriptors

    async def main():
        async with Hub(_config(tmp_path, press_scene, history=False)) as hub:
            c = await _client(hub, wait_for)
            relay = hub._foxglove.relay.pid
            assert descriptors(hub._foxglove.port, ESTABLISHED) == []  # not in the hub's process
            accepted = descriptors(hub._foxglove.port, ESTABLISHED, pid=relay)
            assert len(accepted) == 1
            with socket.socket(fileno=_their_descriptor(relay, accepted[0])) as s:
                assert s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
            await c.close()

    run(main())


def test_mesh_and_frames_on_subscribe_and_the_latest_scene_always_drawn(tmp_path, press_scene, run,
                                                                         wait_for):
    from wott_hub.hub import Hub

    async def main():
        async with Hub(_config(tmp_path, press_scene, history=False, scene_hz=5.0)) as hub:
            c = await _client(hub, wait_for)
            await c.subscribe("/tf", "/pad/scene/skin", "/pad/scene/deformation")
            await wait_for(lambda: c.of("/tf") and c.of("/pad/scene/skin"), what="frames and mesh at once")
            tf = decode("foxglove.FrameTransforms", *_schema(c, "/tf", c.of("/tf")[0][1]))
            assert [(t.parent_frame_id, t.child_frame_id) for t in tf.transforms] == [("wott_hub", "pad")]
            first = c.of("/pad/scene/skin")[0][1]
            mesh = decode("foxglove.SceneUpdate", *_schema(c, "/pad/scene/skin", first))
            assert mesh.entities[0].frame_id == "pad" and len(mesh.entities[0].triangles[0].indices) % 3 == 0

            def drawn():
                return [len(decode("foxglove.SceneUpdate", *_schema(c, "/pad/scene/deformation", p))
                            .entities[0].triangles) for _, p in c.of("/pad/scene/deformation")]

            # the press ends with a rest packet (intensity 0): at 5 scenes/s it arrives between two
            # slots, and is still drawn (an empty scene after a deformed one), by the timer
            def rest_after_press() -> bool:
                n = drawn()
                return any(a and not b for a, b in zip(n, n[1:], strict=False))

            await wait_for(rest_after_press, timeout=30, what="the rest state drawn after a press")
            times = [t for t, _ in c.of("/pad/scene/deformation")]
            assert all(b - a >= 0.18e9 for a, b in zip(times, times[1:], strict=False))  # 5 a second at most
            await c.close()

    run(main())


def _schema(c: FoxClient, topic: str, payload: bytes) -> tuple[bytes, bytes]:
    import base64

    return base64.b64decode(c.channels[topic]["schema"]), payload


def test_bad_clients_change_nothing_for_the_others(tmp_path, press_scene, run, wait_for):
    import websockets

    from wott_hub.hub import Hub

    async def main():
        async with Hub(_config(tmp_path, press_scene)) as hub:
            good = await _client(hub, wait_for)
            await good.subscribe(SKIN)
            await wait_for(lambda: len(good.of(SKIN)) >= 5, what="the good client's first packets")
            bad = await _client(hub, wait_for)
            for frame in ("not json", b"\x07garbage", json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": 1, "channelId": 999_999}]}), json.dumps({"op": "subscribe"}), json.dumps([1, 2]),
                    b"\x01" + b"\xff" * 4096, json.dumps({"op": "unsubscribe", "subscriptionIds": [42]})):
                await bad.ws.send(frame)
            await wait_for(lambda: len(bad.status) >= 5, what="an error status for each bad request")
            assert all(s["level"] == 2 for s in bad.status)  # error level, the connection kept
            assert any("Unknown channel" in s["message"] for s in bad.status)
            before = len(good.of(SKIN))
            bad.ws.transport.abort()  # and gone without a close handshake
            await wait_for(lambda: len(good.of(SKIN)) >= before + 30, what="the good client still served")
            old = await FoxClient.connect(hub.describe()["foxglove"].replace("ws://", "ws://"),
                                          subprotocols=("foxglove.sdk.v1",))
            await old.close()
            with pytest.raises(websockets.InvalidStatus) as refused:  # the protocol's old name alone
                await websockets.connect(hub.describe()["foxglove"], subprotocols=["foxglove.websocket.v1"])
            assert refused.value.response.status_code == 400
            await good.close()
            assert await asyncio.to_thread(hub.flush_history)
            return good

    good = run(main())
    # none lost: every packet recorded between the good client's first and last is at the client
    from wott_hub.history import HistoryReader, create_engine, database_url

    got = [t for t, _ in good.of(SKIN)]
    engine = create_engine(database_url(tmp_path / "hub.db"))
    pages = HistoryReader(engine).pages("pad", got[0], got[-1], ["skinDeformedDetection"])
    recorded = [r.t_ns for page in pages for r in page]
    engine.dispose()
    assert got == recorded


def test_an_image_reaches_a_subscriber_of_its_camera(tmp_path, press_scene, run, wait_for):
    """Issue 29's camera images are not on the hub yet: a hand-made one through the endpoint's entry."""
    import numpy as np

    from wott_hub.hub import Hub
    from wott_hub.robotics.raw_signals import ImageFrame

    png = b"\x89PNG\r\n\x1a\n" + b"\x00" * 64
    raw = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)

    async def main():
        async with Hub(_config(tmp_path, press_scene, history=False)) as hub:
            c = await _client(hub, wait_for)
            live = hub._foxglove
            for cam, data in (("left", png), ("right", raw)):  # the first image advertises the camera
                live.image("pad", ImageFrame(cam, 1, data))
            await wait_for(lambda: "/pad/camera/left/compressed" in c.channels
                           and "/pad/camera/right/raw" in c.channels, what="the cameras advertised")
            await c.subscribe("/pad/camera/left/compressed", "/pad/camera/right/raw")
            await wait_for(lambda: live.wanted("/pad/camera/right/raw"), what="the subscription known")
            live.image("pad", ImageFrame("left", 2_000_000_001, png))
            live.image("pad", ImageFrame("right", 2_000_000_002, raw))
            await wait_for(lambda: c.of("/pad/camera/left/compressed") and c.of("/pad/camera/right/raw"),
                           what="both images")
            await c.close()
            return c

    c = run(main())
    (t, p), = c.of("/pad/camera/left/compressed")
    img = decode("foxglove.CompressedImage", *_schema(c, "/pad/camera/left/compressed", p))
    assert (t, img.format, img.data, img.frame_id) == (2_000_000_001, "png", png, "pad")
    (t, p), = c.of("/pad/camera/right/raw")
    img = decode("foxglove.RawImage", *_schema(c, "/pad/camera/right/raw", p))
    assert (img.width, img.height, img.encoding, img.step, img.data) == (6, 4, "rgb8", 18, raw.tobytes())


def test_off_loopback_only_when_told_and_bad_tables_in_one_line(tmp_path):
    from wott_hub.config import HubConfig
    from wott_hub.errors import ConfigError
    from wott_hub.hub import Hub
    from wott_hub.robotics.config import FoxgloveConfig, check_bind

    cfg = HubConfig(http_port=0, ws_port=None, history=False, foxglove=FoxgloveConfig(port=0, host="0.0.0.0"))
    with pytest.raises(ConfigError, match="refusing to serve Foxglove on 0.0.0.0"):
        Hub(cfg)
    check_bind(FoxgloveConfig(port=0, host="0.0.0.0", insecure=True), insecure=False)  # told: allowed
    check_bind(FoxgloveConfig(port=0, host="0.0.0.0"), insecure=True)  # wott-hub run --insecure
    check_bind(FoxgloveConfig(port=0, host="::1"), insecure=False)
    cases = {
        '[foxglove]\nport = 8765\nhost = "0.0.0.0"\n': "refusing to serve Foxglove on 0.0.0.0",
        "[foxglove]\nport = 70000\n": "[foxglove].port",
        "[foxglove]\nscene_hz = 30\n": "[foxglove].port: missing",
        "[foxglove]\nport = 1\nsceen_hz = 3\n": "sceen_hz",
        "[foxglove]\nport = 1\nscene_hz = 0\n": "[foxglove].scene_hz",
    }
    for text, words in cases.items():
        path = tmp_path / "hub.toml"
        path.write_text(text + '[hub]\nhttp_port = 0\nws_port = false\nhistory = false\n')
        done = subprocess.run([WOTT_HUB, "run", "-c", str(path)], capture_output=True, text=True, timeout=60)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and words in lines[0], (text, done.stderr)
