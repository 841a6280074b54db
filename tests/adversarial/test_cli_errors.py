"""Issue 33 item 13: every mistake a person can make on the command line ends with one ``error:`` line
and an exit code, never a traceback: each case the issue found, a mistyped option or value of any
command, a file the system refuses; and ``tls selfsigned`` does not overwrite a key unless told to.

Each case runs the real command in a subprocess.
"""

from __future__ import annotations

import json

import pytest

from wott_hub.events.record import KIND_EVENT, Record
from wott_hub.history import HistoryWriter, create_engine, database_url, upgrade


@pytest.fixture(scope="module")
def db(tmp_path_factory) -> str:
    path = str(tmp_path_factory.mktemp("errors") / "h.db")
    eng = create_engine(database_url(path))
    upgrade(eng)
    w = HistoryWriter(eng, interval_s=0.01, integrity_check=False)
    start = w.register_thing("d", td=json.dumps({"title": "d"}))
    w.start()
    for i in range(2000):
        w.submit(Record("d", start + i + 1, KIND_EVENT, "tick", 1_700_000_000 * 10**9 + i * 10**6,
                        json.dumps({"i": i, "pad": "x" * 200})))
    assert w.flush(30)
    w.stop()
    eng.dispose()
    return path


def test_run_with_an_unknown_log_level(cli, one_error_line):
    line = one_error_line(cli("run", "--log-level", "bogus"), 2)
    assert "'--log-level'" in line and "'bogus' is not one of 'debug', 'info', 'warning', 'error'" in line
    assert line.endswith("(see wott-hub run --help)")


def test_tokens_create_into_a_folder_that_cannot_be(cli, one_error_line, tmp_path):
    line = one_error_line(cli("tokens", "create", "x", "--file", "/proc/x/t.json"), 2)
    assert line == "error: --file '/proc/x/t.json': cannot write the token file: No such file or directory"


def test_history_export_onto_a_full_disk(cli, one_error_line, db):
    res = cli("history", "export", "--device", "d", "--database", db, "--output", "/dev/full")
    line = one_error_line(res, 1)
    assert line == "error: --output '/dev/full': No space left on device; the file is incomplete"


def test_history_export_to_a_full_standard_output(cli, db, tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    exe = str(Path(sys.executable).with_name("wott-hub"))
    with open("/dev/full", "w") as full:
        res = subprocess.run([exe, "history", "export", "--device", "d", "--database", db], stdout=full,
                             stderr=subprocess.PIPE, text=True, timeout=120)
    assert res.returncode == 1 and "Traceback" not in res.stderr
    assert res.stderr.strip().splitlines() == ["error: No space left on device"]


def test_tls_selfsigned_into_a_folder_that_cannot_be(cli, one_error_line):
    line = one_error_line(cli("tls", "selfsigned", "--out", "/proc/nope"), 2)
    assert line.startswith("error: --out '/proc/nope': cannot write the pair: ")


def test_tls_selfsigned_keeps_an_existing_pair_unless_forced(cli, one_error_line, tmp_path):
    res = cli("tls", "selfsigned", "--out", str(tmp_path))
    assert res.returncode == 0, res.stderr
    key = (tmp_path / "key.pem").read_bytes()
    line = one_error_line(cli("tls", "selfsigned", "--out", str(tmp_path)), 4)
    assert line == (f"error: {tmp_path} has cert.pem and key.pem already: keep them, or replace them "
                    "with --force")
    assert (tmp_path / "key.pem").read_bytes() == key
    res = cli("tls", "selfsigned", "--out", str(tmp_path), "--force")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "key.pem").read_bytes() != key


@pytest.mark.parametrize(("args", "says"), [
    (("history", "lst"), "no such command 'lst'"),
    (("history", "list", "--bogus"), "no such option: --bogus"),
    (("history", "export"), "missing option '--device'"),
    (("history", "audit", "--limit", "0"), "'--limit'"),
    (("td", "show", "--shape", "sphere"), "'sphere' is not one of 'barrel', 'flat', 'cylinder'"),
    (("tls", "selfsigned", "--out", "x", "--days", "99999"), "'--days'"),
    (("--bogus",), "no such option: --bogus"),
])
def test_a_mistyped_command_option_or_value_is_one_line(cli, one_error_line, args, says):
    line = one_error_line(cli(*args), 2)
    assert says in line.lower(), line
    assert line.endswith("--help)")


def test_a_bare_group_still_shows_its_help(cli):
    res = cli("history")
    assert "Usage: wott-hub history" in res.stdout + res.stderr and "Traceback" not in res.stderr


@pytest.mark.parametrize("source", ["/nonexistent/td.json", "-"])
def test_td_validate_of_nothing_readable(cli, one_error_line, source):
    res = cli("td", "validate", source, input="{not json")
    line = one_error_line(res, 2)
    assert line.startswith(f"error: {source}: ") and ("no such file" in line or "not JSON" in line)


def test_td_validate_of_an_unreachable_url(cli, one_error_line):
    line = one_error_line(cli("td", "validate", "http://127.0.0.1:9/wot/x"), 1)
    assert line.startswith("error: http://127.0.0.1:9/wot/x: cannot fetch: ")
