"""Issue 48 item 10, the real CLI: ``wott-hub config check`` runs the same validation as ``run`` (it
approved what ``run`` refused, or what broke it with a traceback), a deeply nested TOML is one line (it
printed a 2,997-line RecursionError), a Foxglove port in use is one line, and ids are one regardless
of case everywhere (``addDevice`` of ``PAD`` was a 409 beside ``Pad`` while ``GET /wot/pad`` was a 404).
What each attack did is measured as what a user reads: the lines printed and the exit code."""

from __future__ import annotations

import socket

import httpx
import pytest

from wott_hub.config import HubConfig
from wott_hub.network import DiscoveryConfig

from . import surroundings as S


def check(cli, folder, body: str):
    path = S.write_config(folder, body)
    return cli("config", "check", "-c", str(path), timeout=60)


def errors_of(res) -> list[str]:
    assert "Traceback" not in res.stdout + res.stderr, res.stderr[-3000:]
    return [ln for ln in res.stderr.splitlines() if ln.startswith("error: ")]


def test_a_deeply_nested_toml_is_one_line(cli, tmp_path):
    res = check(cli, tmp_path, "x = " + "[" * 5000 + "]" * 5000 + "\n")
    assert res.returncode == 2, res.stderr[-2000:]
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) <= 2 and "nested too deeply" in lines[0], lines[:5]  # before: 2,997 lines


@pytest.mark.parametrize(("body", "says"), [
    ("[hub]\nhttp_port = 18765\n[foxglove]\nport = 18765\n",
     "[foxglove].port: 18765 is also [hub].http_port"),
    ("[hub]\nws_port = 18766\n[foxglove]\nport = 18766\n", "[foxglove].port: 18766 is also [hub].ws_port"),
    ('[foxglove]\nport = 0\nhost = "0.0.0.0"\n', "refusing to serve Foxglove on 0.0.0.0"),
    ('[hub]\nhost = "0.0.0.0"\n', "refusing to listen on 0.0.0.0 without credentials"),
], ids=["foxglove-on-http-port", "foxglove-on-ws-port", "foxglove-off-loopback", "open-hub"])
def test_config_check_refuses_what_run_refuses(cli, one_error_line, tmp_path, body, says):
    res = check(cli, tmp_path, body)
    assert res.returncode == 2 and any(says in ln for ln in errors_of(res)), res.stderr
    path = tmp_path / "hub.toml"
    run = cli("run", "-c", str(path), "--no-history", "--port", "0" if "http_port" not in body else "18765",
              timeout=60)
    assert says in one_error_line(run, 2)  # before: run refused with a traceback, or check approved


def test_device_ids_differing_only_in_case_are_refused(cli, tmp_path):
    body = "".join(f'[[device]]\nid = "{i}"\nfamily = "scene"\nshape = "flat"\n' for i in ("Pad", "pad"))
    res = check(cli, tmp_path, body)
    assert res.returncode == 2, res.stderr
    said = "device[1].id: 'pad' is used by another device ('Pad'"
    assert any(said in ln for ln in errors_of(res)), res.stderr


def test_a_foxglove_port_in_use_is_one_line(cli, one_error_line, tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        path = S.write_config(tmp_path, S.press_table())
        res = cli("run", "-c", str(path), "--no-history", "--port", "0", "--ws-port", "0",
                  "--foxglove-port", str(port), timeout=90)
    line = one_error_line(res, 1)  # before: a traceback (FoxgloveError)
    assert "Foxglove" in line and "in use" in line, line


@pytest.fixture(scope="module")
def hub(hub_thread, press_scene):
    ht = hub_thread(HubConfig(http_port=0, ws_port=0, history=False, discovery=DiscoveryConfig.off(),
                              devices=(press_scene("Pad"),))).start()
    yield ht
    ht.stop()


def test_ids_are_one_regardless_of_case_over_http(hub):
    r = httpx.get(f"{hub.url}/wot/pad", timeout=10)
    assert r.status_code == 200 and r.json()["title"] == "Pad", r.text  # before: 404
    add = httpx.post(f"{hub.url}/wot/hub/actions/addDevice", json={"id": "PAD", "family": "scene",
                                                                   "settings": {"shape": "flat"}}, timeout=30)
    assert add.status_code == 409 and "'Pad'" in add.json()["detail"], add.text
    streamed = httpx.get(f"{hub.url}/wot/PAD/properties/skinShape", timeout=10)
    assert streamed.status_code == 200, streamed.text
