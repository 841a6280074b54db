"""Foxglove's own client library, ``@foxglove/ws-protocol`` (npm, pinned by package-lock.json),
against a real hub's Foxglove endpoint: it connects, is advertised every channel, subscribes, and
receives the skin's scenes (``foxglove.SceneUpdate``), the contacts (their scene and their raw
JSON), the actions' log, the frames and a camera image, every one decoded here from the schema
the channel carries. Half way it subscribes to a channel that does not exist and sends garbage:
it gets error statuses and keeps receiving."""

from __future__ import annotations

import base64
import json
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "robotics"))
from foxglove_proto import decode  # noqa: E402  # tests/robotics, not a package under importlib mode

PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(48))
HERE = Path(__file__).resolve().parent


class _Script:
    """``node foxglove.mjs``: its JSON lines one at a time; killed at the end. Node 20 has the browser's
    WebSocket behind ``--experimental-websocket`` (on by default from Node 22)."""

    def __init__(self, node: list[str], *args: str) -> None:
        has = subprocess.run([*node, "-e", "process.exit(typeof WebSocket === 'function' ? 0 : 1)"],
                             timeout=30).returncode == 0
        flags = [] if has else ["--experimental-websocket"]
        self.proc = subprocess.Popen([*node, *flags, str(HERE / "foxglove.mjs"), *args], cwd=HERE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.pump = threading.Thread(target=self._pump, daemon=True)
        self.pump.start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def next(self, timeout: float) -> dict:
        try:
            line = self.lines.get(timeout=timeout)
        except queue.Empty:
            line = None
        if line is None:
            self.proc.kill()
            err = self.proc.stderr.read() if self.proc.stderr is not None else ""
            raise AssertionError(f"foxglove.mjs ended or stalled: {err[-3000:]}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)
        self.pump.join(10)
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()


@pytest.fixture(scope="module")
def fox_hub(hub_thread, press_scene, tmp_path_factory):
    from wott_hub.config import HubConfig
    from wott_hub.robotics.config import FoxgloveConfig

    cfg = HubConfig(http_port=0, ws_port=None, history=False, devices=(press_scene("pad"),),
                    foxglove=FoxgloveConfig(port=0, scene_hz=10.0))
    hub = hub_thread(cfg).start()
    yield hub
    hub.stop()


def _image(hub, t_ns: int) -> None:
    from wott_hub.robotics.raw_signals import ImageFrame

    hub.hub._foxglove.image("pad", ImageFrame("left", t_ns, PNG))  # issue 29's images: by hand


@pytest.fixture
def fox_script(node_wot):
    started: list[_Script] = []

    def start(*args: str) -> _Script:
        started.append(_Script(node_wot, *args))
        return started[-1]

    yield start
    for s in started:
        s.close()


def test_foxgloves_client_library_receives_scenes_contacts_logs_frames_and_images(fox_hub, fox_script):
    fox_hub.call(_image, fox_hub, 1)  # the camera's channel exists before the client connects
    s = fox_script(fox_hub.hub.describe()["foxglove"], "6")
    ready = s.next(timeout=60)["ready"]
    assert "/pad/camera/left/compressed" in ready and "/pad/scene/deformation" in ready
    deadline = time.monotonic() + 3
    k = 0
    while time.monotonic() < deadline:  # a camera at ~20 Hz while the client listens
        k += 1
        fox_hub.call(_image, fox_hub, 2_000_000_000 + k)
        time.sleep(0.05)
    report = s.next(timeout=60)["report"]
    topics = report["topics"]
    assert report["protocol"] == "foxglove.sdk.v1"
    assert report["serverInfo"]["name"] == "wott-hub"

    def messages(topic: str, name: str) -> list:
        t = topics[topic]
        assert t["count"] >= 1 and t["schemaName"] == name, (topic, t["count"], t["schemaName"])
        if t["schemaEncoding"] == "protobuf":
            schema = base64.b64decode(t["schema"])
            return [decode(name, schema, base64.b64decode(p)) for p in t["payloads"]]
        return [json.loads(base64.b64decode(p)) for p in t["payloads"]]

    mesh, = messages("/pad/scene/skin", "foxglove.SceneUpdate")[:1]
    assert mesh.entities[0].id == "skin" and len(mesh.entities[0].triangles[0].points) > 100
    scenes = messages("/pad/scene/deformation", "foxglove.SceneUpdate")
    assert all(sc.entities[0].frame_id == "pad" for sc in scenes)
    arrows = messages("/pad/scene/contacts", "foxglove.SceneUpdate")
    assert arrows and all(a.entities[0].id == "contacts" for a in arrows)
    assert any(len(a.entities[0].arrows) for a in arrows) or topics["/pad/scene/contacts"]["count"] > 3
    contacts = messages("/pad/properties/contactInformation", "wott.pad.contactInformation")
    core = {"numOfContacts", "contactLocations", "contactForces"}  # and contactIds while touched
    assert all(core <= set(c) <= core | {"contactIds"} for c in contacts)
    logs = messages("/pad/log", "foxglove.Log")
    assert {lg.name for lg in logs} == {"pad"} and logs[0].message
    tf, = messages("/tf", "foxglove.FrameTransforms")[:1]
    assert [t.child_frame_id for t in tf.transforms] == ["pad"]
    images = messages("/pad/camera/left/compressed", "foxglove.CompressedImage")
    assert images[0].format == "png" and images[0].data == PNG
    assert topics["/pad/camera/left/compressed"]["count"] >= 10
    skins = topics["/pad/events/skinDeformedDetection"]
    times = [int(t) for t in skins["times"]]
    assert times == sorted(times) and skins["count"] >= 60  # 60 Hz for 6 s, from the start
    # the bad requests: answered with error statuses, the client served on
    statuses = report["statuses"]
    assert any(st["level"] == 2 and "987654" in st["message"] for st in statuses), statuses
    assert report["afterGarbage"] >= 50
