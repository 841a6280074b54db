"""Raw signals on a real hub (issue 29): each camera's latest image and a taxel array's pressure grid as
properties whose forms say the media type, encoded only for a reader, in a worker process too; bad
input gets a 400 problem+json naming the parameter; a camera that opts in has its images recorded."""

from __future__ import annotations

import asyncio
import base64
import io
import json

import httpx
import numpy as np
import pytest
from PIL import Image

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig
from wott_hub.plugin_api import DeviceConfig, Driver, RawSample, RawSignal, ServesRawSignals, TactileFrame
from wott_hub.td.validate import validate_td

PAD = DeviceConfig("pad-cam", "flat-vision", {"source": "sim", "fps": 15.0})
TAXEL = DeviceConfig("grid", "taxel-array", {"simulate": True, "rate_hz": 30.0})


@pytest.fixture(scope="module")
def hub(tmp_path_factory, hub_thread):
    db = tmp_path_factory.mktemp("raw") / "hub.db"
    cfg = HubConfig(http_port=0, ws_port=0, database=str(db), history_batch_ms=20,
                    discovery=DiscoveryConfig.off(), devices=(PAD, TAXEL))
    h = hub_thread(cfg).start()
    yield h
    h.stop()


def _td(hub, thing: str) -> dict:
    return httpx.get(f"{hub.url}/wot/{thing}").json()


def test_the_tds_declare_the_raw_signals_with_their_media_types(hub):
    pad, grid = _td(hub, "pad-cam"), _td(hub, "grid")
    assert validate_td(pad) == [] and validate_td(grid) == []
    image = pad["properties"]["rawImage"]
    assert image["uriVariables"]["camera"]["enum"] == ["camera"] and image["type"] == "string"
    types = [f["contentType"] for f in image["forms"]]
    assert types == ["application/json", "image/png", "image/jpeg", "application/x-npy", "application/json",
                     "multipart/x-mixed-replace;boundary=frame"]
    observe = image["forms"][-2]  # the plain observe form first: wotpy observes through it (issue 48)
    assert observe["href"].endswith("/properties/rawImage/observe") and observe["subprotocol"] == "sse"
    stream = image["forms"][-1]
    assert stream["op"] == ["observeproperty", "unobserveproperty"] and stream["subprotocol"] == "stream"
    assert "{?camera,maxRate}" in stream["href"]
    assert "{" not in image["forms"][0]["href"]  # wotpy reads its first form as is
    assert "pressureGrid" in grid["properties"] and "rawImage" not in grid["properties"]
    assert [f["contentType"] for f in grid["properties"]["pressureGrid"]["forms"]] == [
        "application/json", "application/x-npy", "application/json", "application/json"]
    assert "rawImageRecorded" not in pad["events"]  # not recorded unless the device opts in
    everything = httpx.get(f"{hub.url}/wot/pad-cam/properties").json()
    assert "rawImage" not in everything and "skinShape" in everything  # never encoded for a bulk read


def _read(hub, thing: str, query: str = "", eventually=None) -> httpx.Response:
    def ok():
        r = httpx.get(f"{hub.url}/wot/{thing}/properties/{query}", timeout=20)
        return r if r.status_code != 503 else None  # 503: no frame yet
    return eventually(ok, timeout=30, what=f"a frame of {thing}")


def test_a_raw_image_read_while_the_camera_runs_decodes_to_the_cameras_size(hub, eventually):
    npy = _read(hub, "pad-cam", "rawImage?format=npy", eventually)
    assert npy.headers["content-type"] == "application/x-npy"
    image = np.load(io.BytesIO(npy.content), allow_pickle=False)
    assert image.shape == (480, 640, 1) and image.dtype == np.uint8 and image.std() > 0
    for fmt, kind in (("png", "PNG"), ("jpeg", "JPEG")):
        r = _read(hub, "pad-cam", f"rawImage?format={fmt}&camera=camera", eventually)
        assert r.headers["content-type"] == f"image/{fmt}"
        with Image.open(io.BytesIO(r.content)) as img:
            assert (img.format, img.size) == (kind, (640, 480))
    js = _read(hub, "pad-cam", "rawImage", eventually)
    with Image.open(io.BytesIO(base64.b64decode(js.json()))) as img:
        assert img.size == (640, 480)


def test_the_pressure_grid_as_json_and_as_an_array(hub, eventually):
    value = _read(hub, "grid", "pressureGrid", eventually).json()
    assert (value["rows"], value["cols"]) == (16, 16) and len(value["pressure"]) == 16
    grid = np.load(io.BytesIO(_read(hub, "grid", "pressureGrid?format=npy", eventually).content))
    assert grid.shape == (16, 16) and grid.dtype == np.float32


@pytest.mark.parametrize(("query", "named"), [
    ("rawImage/stream?maxRate=-1", "maxRate"), ("rawImage/stream?maxRate=1e9", "maxRate"),
    ("rawImage/stream?maxRate=fast", "maxRate"), ("rawImage/stream?maxRate=nan", "maxRate"),
    ("rawImage?camera=left", "camera"), ("rawImage/stream?camera=left", "camera"),
    ("rawImage?format=gif", "format"), ("pressureGrid?format=png", "format")])
def test_bad_input_is_a_400_problem_naming_the_parameter(hub, query, named):
    thing = "grid" if query.startswith("pressure") else "pad-cam"
    r = httpx.get(f"{hub.url}/wot/{thing}/properties/{query}", timeout=10)
    assert r.status_code == 400 and r.headers["content-type"] == "application/problem+json"
    assert f"parameter '{named}'" in r.json()["detail"]


def test_unknown_raw_properties_and_writes_are_refused(hub):
    assert httpx.get(f"{hub.url}/wot/grid/properties/rawImage").status_code == 404  # a taxel has no camera
    assert httpx.get(f"{hub.url}/wot/nothing/properties/rawImage").status_code == 404
    r = httpx.put(f"{hub.url}/wot/pad-cam/properties/rawImage", json="x")
    assert r.status_code == 405 and "read-only" in r.json()["detail"]


def test_the_live_stream_is_jpeg_parts_a_browser_shows_and_the_grid_an_sse_stream(hub, eventually):
    _read(hub, "pad-cam", "rawImage?format=npy", eventually)  # the camera runs
    stamps: list[int] = []
    with httpx.stream("GET", f"{hub.url}/wot/pad-cam/properties/rawImage/stream?maxRate=20", timeout=30) as r:
        assert r.headers["content-type"] == "multipart/x-mixed-replace;boundary=frame"
        buf = b""
        for chunk in r.iter_bytes():
            buf += chunk
            while buf.count(b"--frame\r\n") >= 2:  # a whole part: up to the next boundary
                head, rest = buf.split(b"--frame\r\n", 2)[1:3]
                headers, body = head.split(b"\r\n\r\n", 1)
                assert b"Content-Type: image/jpeg" in headers
                with Image.open(io.BytesIO(body[:-2])) as img:
                    assert img.size == (640, 480)
                stamps.append(int(headers.split(b"X-Timestamp-Ns: ")[1].split(b"\r\n")[0]))
                buf = b"--frame\r\n" + rest
            if len(stamps) >= 3:
                break
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)  # each frame once
    got = []
    grid_stream = f"{hub.url}/wot/grid/properties/pressureGrid/stream?maxRate=30"
    with httpx.stream("GET", grid_stream, timeout=30) as r:
        assert r.headers["content-type"].startswith("text/event-stream")
        for line in r.iter_lines():
            if line.startswith("data: "):
                got.append(json.loads(line[6:]))
                if len(got) == 2:
                    break
    assert got[0]["timeStamp"] < got[1]["timeStamp"] and got[1]["rows"] == 16


class StillCamera(Driver, ServesRawSignals):
    """A camera whose one image never changes (the frame time stays), and a second that always fails."""

    def __init__(self, desc) -> None:
        super().__init__(desc)
        self.raw_signals = (RawSignal("still", "image", (48, 64)), RawSignal("broken", "image", (48, 64)))
        self.image = RawSample(123, np.full((48, 64, 3), 7, np.uint8))

    async def frames(self):
        while True:
            yield TactileFrame(1, np.zeros((self.description.mesh.n_nodes, 3)))
            await asyncio.sleep(0.05)

    def raw_sample(self, name: str) -> RawSample | None:
        if name == "broken":
            raise RuntimeError("the sensor's cable")
        return self.image


def test_nothing_is_encoded_until_read_then_once_per_frame_and_a_failing_camera_marks_its_device(hub):
    from dataclasses import replace

    from wott_hub.examples import example_device

    async def add():
        await hub.hub.add_driver(StillCamera(replace(example_device("flat"), id="still", title="still")))

    hub.call(add)
    source = hub.hub.devices["still"].raw
    assert source.encoded == 0  # frames flow, nobody reads: nothing encoded
    for _ in range(4):
        r = httpx.get(f"{hub.url}/wot/still/properties/rawImage?format=npy&camera=still")
        assert np.load(io.BytesIO(r.content)).shape == (48, 64, 3)
    assert source.encoded == 1  # one frame, four readers: encoded once
    r = httpx.get(f"{hub.url}/wot/still/properties/rawImage?format=png&camera=broken")
    detail = r.json()["detail"]
    assert r.status_code == 502 and "the sensor's cable" in detail and "'still'" in detail
    assert httpx.get(f"{hub.url}/healthz").status_code == 200
    assert httpx.get(f"{hub.url}/wot/still/properties/rawImage?format=npy&camera=still").status_code == 200
    hub.call(hub.hub.remove_device, "still")


def test_a_device_in_a_worker_process_is_sampled_over_its_pipe(tmp_path, hub_thread, eventually):
    cfg = HubConfig(http_port=0, ws_port=0, history=False, workers=1, discovery=DiscoveryConfig.off(),
                    devices=(PAD,))
    h = hub_thread(cfg).start()
    try:
        assert h.hub.devices["pad-cam"].worker is not None
        r = _read(h, "pad-cam", "rawImage?format=npy", eventually)
        assert np.load(io.BytesIO(r.content)).shape == (480, 640, 1)
        assert httpx.get(f"{h.url}/wot/pad-cam/properties/rawImage?camera=x").status_code == 400
    finally:
        h.stop()


def test_a_camera_that_opts_in_has_its_images_recorded(tmp_path, hub_thread, sse_events):
    cam = DeviceConfig("rec-cam", "flat-vision", {"source": "sim", "fps": 10.0, "record_raw_hz": 2.0})
    cfg = HubConfig(http_port=0, ws_port=0, database=str(tmp_path / "hub.db"), history_batch_ms=20,
                    discovery=DiscoveryConfig.off(), devices=(cam,))
    h = hub_thread(cfg).start()
    try:
        td = _td(h, "rec-cam")
        assert "rawImageRecorded" in td["events"] and validate_td(td) == []
        ev = sse_events(f"{h.url}/wot/rec-cam/events/rawImageRecorded", 1, timeout=60)[0]
        value = json.loads(ev.data)
        shape = (value["camera"], value["width"], value["height"], value["channels"])
        assert shape == ("camera", 640, 480, 1)
        with Image.open(io.BytesIO(base64.b64decode(value["image"]))) as img:
            assert img.size == (640, 480)
        assert h.hub.flush_history(10)
        hub_td = _td(h, "hub")
        form = hub_td["actions"]["historyRecords"]["forms"][0]["href"]
        lines = httpx.post(form, json={"device": "rec-cam", "names": ["rawImageRecorded"]}).text.splitlines()
        assert lines and json.loads(lines[0])["data"]["camera"] == "camera"
    finally:
        h.stop()
