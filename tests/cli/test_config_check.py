"""Issue 32 item 1, issue 33 item 13: ``wott-hub config check`` reports every problem of a config at
once (file, table, key, "did you mean"), with the exit code of its class; ``run`` refuses to start on
the same problems, one line each.

Each case is a real config file read by the real command (a subprocess, as a person runs it); the
devices that ``--open`` opens are real: the taxel simulator on its pty, a scene, and a serial port
that is not there.
"""

from __future__ import annotations

import json
import re

import pytest

GOOD = """\
[hub]
name = "lab"

[[device]]
id = "pad"
family = "taxel-array"
simulate = true
rate_hz = 50

[[device]]
id = "finger"
family = "scene"
shape = "flat"

[[device.step]]
kind = "press"
at = [11.25, 11.25, 4.0]
start_s = 0.1
duration_s = 0.5
depth_mm = 1.0
radius_mm = 4.0
"""


def _write(tmp_path, text: str, name: str = "hub.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _errors(res) -> list[str]:
    """The ``error:`` lines, each without the list of known keys an unknown key's line carries."""
    assert "Traceback" not in res.stderr + res.stdout, res.stderr
    return [re.sub(r" \(known: [^)]*\)", "", ln.removeprefix("error: "))
            for ln in res.stderr.splitlines() if ln.startswith("error: ")]


# one config per class of error: (what the file holds, the line the check prints after "<file>: ")
CASES = {
    "unknown table": ("[securty]\ncert = 'c.pem'\n", "unknown table [securty]; did you mean [security]?"),
    "devices misspelt": ("[[devices]]\nid = 'a'\nfamily = 'scene'\n",
                         "unknown table [devices]; did you mean [[device]]?"),
    "unknown hub key": ("[hub]\nworkrs = 2\n", "did you mean 'workers'?"),
    "value out of bounds": ("[hub]\nworkers = 100000\n",
                            "[hub].workers: a whole number of processes (0: none), got 100000; "
                            "must be from 0 to 64"),
    "wrong type": ("[directory]\nttl_s = 'long'\n",
                   "[directory].ttl_s: a positive number of seconds, got 'long'"),
    "rule across keys": ("[security]\ncert = 'c.pem'\n",
                         "[security]: cert and key go together (TLS needs both)"),
    "device without id": ("[[device]]\nfamily = 'scene'\nshape = 'flat'\nscene = 's.toml'\n",
                          "device[0].id: required, missing"),
    "duplicate id": ("[[device]]\nid = 'a'\nfamily = 'scene'\nscene = 's.toml'\n"
                     "[[device]]\nid = 'a'\nfamily = 'scene'\nscene = 's.toml'\n",
                     "device[1].id: 'a' is used by another device"),
    "unknown family": ("[[device]]\nid = 'a'\nfamily = 'taxel'\nsimulate = true\n",
                       "device[0].family: unknown family 'taxel'; did you mean 'taxel-array'?"),
    "misspelt setting": ("[[device]]\nid = 'a'\nfamily = 'taxel-array'\nsimulte = true\n",
                         "device[0].simulte (device 'a', family 'taxel-array'): unknown setting; "
                         "did you mean 'simulate'?"),
    "setting out of bounds": ("[[device]]\nid = 'a'\nfamily = 'taxel-array'\nsimulate = true\n"
                              "kpa_per_count = 1e300\n",
                              "device[0].kpa_per_count (device 'a', family 'taxel-array'): got 1e+300; "
                              "must be above 0 and at most 10"),
    "setting of a nested table": ("[[device]]\nid = 'a'\nfamily = 'flat-vision'\n"
                                  "optics = { focal_pixels = 3 }\n",
                                  "device[0].optics.focal_pixels (device 'a', family 'flat-vision'): "
                                  "unknown setting; did you mean 'focal_px'?"),
    "setting NaN": ("[[device]]\nid = 'a'\nfamily = 'taxel-array'\nsimulate = true\nrate_hz = nan\n",
                    "rate_hz"),
    "one of two keys": ("[[device]]\nid = 'a'\nfamily = 'scene'\n",
                        "device[0] (device 'a', family 'scene'): needs one of 'scene' or 'step'"),
    "not TOML": ("[hub\n", "not valid TOML"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_class_of_error_is_one_line_naming_file_table_and_key(cli, tmp_path, case):
    text, expected = CASES[case]
    path = _write(tmp_path, text)
    res = cli("config", "check", "--config", str(path))
    assert res.returncode == 2, (res.stdout, res.stderr)
    errors = _errors(res)
    assert len(errors) == 1, res.stderr
    assert errors[0].startswith(f"{path}") and expected in errors[0], errors[0]


def test_every_problem_of_every_table_and_device_at_once(cli, tmp_path):
    path = _write(tmp_path, """\
[hub]
workrs = 2
http_port = 70000

[[device]]
id = "pad"
family = "taxel-array"
simulte = true
kpa_per_count = 1e300

[[device]]
id = "flat"
family = "flat-vison"

[[device]]
id = "pad"
family = "scene"
scene = "s.toml"

[discovery]
browse = "yes"
""")
    res = cli("config", "check", "--config", str(path))
    assert res.returncode == 2
    errors = [e.removeprefix(f"{path}: ") for e in _errors(res)]
    assert errors == [
        "[hub].workrs: unknown key; did you mean 'workers'?",
        "[hub].http_port: a port number (0: any free port), got 70000; must be from 0 to 65535",
        "device[2].id: 'pad' is used by another device",
        "[discovery].browse: true or false, got 'yes'",
    ], res.stderr
    # the tables right, the devices' settings are checked: each device, each setting
    fixed = path.read_text().replace("workrs = 2\nhttp_port = 70000", "workers = 2") \
        .replace('id = "pad"\nfamily = "scene"', 'id = "pad2"\nfamily = "scene"').replace('"yes"', "true")
    path.write_text(fixed)
    res = cli("config", "check", "--config", str(path))
    assert res.returncode == 2
    errors = [e.removeprefix(f"{path}: ") for e in _errors(res)]
    assert errors == [
        "device[0].simulte (device 'pad', family 'taxel-array'): unknown setting; did you mean 'simulate'?",
        "device[0].kpa_per_count (device 'pad', family 'taxel-array'): got 1e+300; "
        "must be above 0 and at most 10",
        "device[1].family: unknown family 'flat-vison'; did you mean 'flat-vision'? "
        "(installed: anyskin, barrel-vision, digit, flat-vision, gelsight-mini, scene, taxel-array, "
        "wot-remote, xela)",
    ], res.stderr
    assert "3 config error(s)" in res.stderr  # not "port missing": that follows from the typo


def test_run_refuses_to_start_with_one_line_per_problem(cli, tmp_path):
    """Issue 33 item 13: ``kpa_per_count = 1e300`` in a [[device]] table is a ConfigError line and exit 2,
    not a hub started with the device failed."""
    path = _write(tmp_path, "[hub]\nhttp_port = 0\nws_port = 0\n\n[[device]]\nid = 'a'\n"
                            "family = 'taxel-array'\nsimulte = true\nkpa_per_count = 1e300\n")
    res = cli("run", "--config", str(path), "--no-history", timeout=120)
    assert res.returncode == 2
    errors = _errors(res)
    assert [e.removeprefix(f"{path}: ").split(":")[0] for e in errors] == [
        "device[0].simulte (device 'a', family 'taxel-array')",
        "device[0].kpa_per_count (device 'a', family 'taxel-array')"]
    assert "running" not in res.stdout and res.stdout == ""


def test_a_good_config_is_ok_and_its_devices_open_and_close(cli, tmp_path):
    path = _write(tmp_path, GOOD)
    res = cli("config", "check", "--config", str(path))
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().endswith(f"{path}: 2 device(s): OK")
    res = cli("config", "check", "--config", str(path), "--open", timeout=180)
    assert res.returncode == 0, res.stderr
    out = res.stdout.splitlines()
    assert "opened pad (taxel-array): 256 nodes, shape rectangularPrism, first frame read; closed" in out
    assert any(line.startswith("opened finger (scene): ") for line in out)
    assert out[-1] == f"{path}: 2 device(s): OK (each opened and closed)"


def test_a_device_that_does_not_open_is_exit_5_and_named(cli, tmp_path):
    missing = tmp_path / "ttyUSB9"
    path = _write(tmp_path, GOOD + f'\n[[device]]\nid = "palm"\nfamily = "taxel-array"\nport = "{missing}"\n')
    res = cli("config", "check", "--config", str(path))
    assert res.returncode == 0, res.stderr  # the settings are right: only opening finds the port missing
    res = cli("config", "check", "--config", str(path), "--open", "--wait", "3", timeout=180)
    assert res.returncode == 5, (res.stdout, res.stderr)
    errors = _errors(res)
    assert len(errors) == 1 and errors[0].startswith(f"{path}: device[2]: opened (256 nodes"), errors
    assert "no frame within 3 s" in errors[0] and str(missing) in errors[0]
    assert "opened pad (taxel-array)" in res.stdout  # the others were opened all the same


def test_json_report_for_scripts(cli, tmp_path):
    path = _write(tmp_path, GOOD.replace("rate_hz = 50", "rate_hz = 50\nrate = 3"))
    res = cli("config", "check", "--config", str(path), "--json")
    assert res.returncode == 2 and res.stderr == ""
    report = json.loads(res.stdout)
    assert report["ok"] is False and len(report["errors"]) == 1 and "rate" in report["errors"][0]
    assert [d["id"] for d in report["devices"]] == ["pad", "finger"]
    assert report["devices"][0]["errors"] == report["errors"]
    path.write_text("[hub\n")
    res = cli("config", "check", "--config", str(path), "--json")
    assert res.returncode == 2 and "not valid TOML" in json.loads(res.stdout)["errors"][0]


def test_a_missing_certificate_is_named_not_none(cli, tmp_path):
    path = _write(tmp_path, "[security]\ncert = 'tls/cert.pem'\nkey = 'tls/key.pem'\n")
    for args in (("config", "check", "--config", str(path)), ("run", "--config", str(path))):
        res = cli(*args)
        errors = _errors(res)
        assert res.returncode == 2 and len(errors) == 1, res.stderr
        assert f"cannot read {tmp_path / 'tls' / 'cert.pem'} and {tmp_path / 'tls' / 'key.pem'}" in errors[0]
        assert "None" not in errors[0]


def test_an_unreadable_config_is_one_line(cli, tmp_path):
    res = cli("config", "check", "--config", str(tmp_path / "nope.toml"))
    errors = _errors(res)
    assert res.returncode == 2 and len(errors) == 1 and "nope.toml: cannot read" in errors[0]


def test_without_a_config_the_demo_fleet_is_checked(cli):
    res = cli("config", "check")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "the demo fleet: 3 device(s): OK"


def test_run_serves_the_others_and_counts_a_device_that_does_not_open(tmp_path):
    """A device whose settings are right but which does not open (its model file is not there) does not
    stop the hub: the banner lists it FAILED and counts it; ``config check --open`` finds it first."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    quiet = ("[hub]\nhttp_port = 0\nws_port = 0\nhistory = false\n\n[directory]\nenabled = false\n\n"
             "[discovery]\nmdns = false\nbrowse = false\n\n")
    path = _write(tmp_path, quiet + GOOD.split("\n", 3)[3]
                  + '\n[[device]]\nid = "arm"\nfamily = "barrel-vision"\nmodel = "missing.onnx"\n')
    exe = str(Path(sys.executable).with_name("wott-hub"))
    check = subprocess.run([exe, "config", "check", "--config", str(path), "--open"], capture_output=True,
                           text=True, timeout=180)
    assert check.returncode == 5 and "missing.onnx" in check.stderr, check.stderr
    log = (tmp_path / "hub.log").open("w")
    proc = subprocess.Popen([exe, "run", "--config", str(path)], stdout=subprocess.PIPE, stderr=log,
                            text=True, env={**os.environ, "COLUMNS": "80"}, cwd=tmp_path)
    try:
        assert proc.stdout is not None
        lines = []
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            if line.startswith("ready in "):
                break
        assert "  devices: 2 serving, 1 FAILED (retried)" in lines, lines
        failed = [line for line in lines if "FAILED:" in line]
        assert len(failed) == 1 and failed[0].split()[0] == "arm" and "missing.onnx" in failed[0]
        served = [line.split()[0] for line in lines if re.match(r"^    \S+ +\S+ +http://", line)]
        assert sorted(served) == ["finger", "pad"]
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(60) == 0
        log.close()


def test_a_database_url_of_no_known_scheme_is_a_config_error(cli, tmp_path):
    path = _write(tmp_path, "[hub]\ndatabase = 'nosuchdb://host/x'\n")
    errors = _errors(res := cli("config", "check", "--config", str(path)))
    assert res.returncode == 2 and len(errors) == 1, res.stderr
    assert errors[0].startswith(f"{path}: [hub].database: cannot use the history database 'nosuchdb://host/x'")
