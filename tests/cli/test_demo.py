"""Issue 32 items 2, 3 and 5 against a real demo hub (``wott-hub run``, no config): each listing command
run as a process at 80 columns cuts no id, time or URL; the banner counts what it lists and its
URLs work (the twin, the ``curl`` line); every example of a ``--help`` and of the docs that runs
against the demo is run, and answers.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[2]


def _env(demo) -> dict[str, str]:
    return {"WOTT_HUB_URL": demo.http, "WOTT_DIRECTORY_URL": f"{demo.http}/"}


DEMO = {"barrel-1", "flatpad-1", "taxel-1"}  # and whatever it adopts on loopback (mDNS browsing is on)


def test_the_banner_counts_what_it_lists_and_states_the_retention(demo):
    assert DEMO <= set(demo.devices)
    assert f"  devices: {len(demo.devices)} serving" in demo.banner
    assert all(url.startswith(f"{demo.http}/wot/") for url in demo.devices.values())
    assert "oldest deleted beyond 500 MB" in " ".join(demo.banner)
    twin = next(line for line in demo.banner if line.startswith("  twin "))
    r = httpx.get(twin.split()[1], timeout=30)
    assert r.status_code == 200 and "text/html" in r.headers["content-type"]


def test_the_banners_curl_line_streams_events(demo):
    assert demo.curl.startswith("curl -N -H 'Accept: text/event-stream' http")
    proc = subprocess.Popen([*shlex.split(demo.curl), "--max-time", "60"], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 60
        seen = []
        while time.monotonic() < deadline and not any(line.startswith("data: {") for line in seen):
            seen.append(proc.stdout.readline())
        assert any(line.startswith("id: ") for line in seen), seen
        assert any(line.startswith("data: {") for line in seen), seen
    finally:
        proc.kill()
        proc.wait(10)


def test_devices_list_at_80_columns(cli, demo):
    res = cli("devices", "list", env=_env(demo))
    assert res.returncode == 0, res.stderr
    assert all(len(line) <= 80 for line in res.stdout.splitlines())
    for did in DEMO:  # its health whole: ok, or degraded while a loaded machine makes it skip frames
        assert re.search(rf"^{did} +\S+ +(ok|degraded)\b", res.stdout, re.M), res.stdout
    rows = json.loads(cli("devices", "list", "--json", env=_env(demo)).stdout)
    assert {r["id"]: r["td"] for r in rows}.items() >= demo.devices.items()


def test_directory_list_at_80_columns_keeps_whole_ids(cli, demo):
    res = cli("directory", "list", env=_env(demo))
    assert res.returncode == 0, res.stderr
    listed = json.loads(cli("directory", "list", "--json", env=_env(demo)).stdout)
    ids = [row["id"] for row in listed]
    assert len([i for i in ids if ":device:" in i]) >= 3
    for tid in ids:
        assert re.search(rf"^{re.escape(tid)}  ", res.stdout, re.M), res.stdout


def test_the_examples_of_directory_query_help_answer_on_the_demo(cli, demo):
    helptext = cli("directory", "query", "--help").stdout
    examples = re.findall(r"'(\$[^']+)'", " ".join(helptext.split()))
    assert len(examples) == 2, helptext
    for query in examples:
        res = cli("directory", "query", query, env=_env(demo))
        assert res.returncode == 0, res.stderr
        assert json.loads(res.stdout), f"{query} finds nothing on the demo"


def _doc_examples() -> list[tuple[str, str]]:
    """Commands of the docs that run against a hub at 127.0.0.1:8080: ``wott-hub devices list|health``,
    ``wott-hub directory query|list`` (code blocks and inline code) and ``curl`` lines (a stream's,
    ``-N``, is the banner's: its own test)."""
    found = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text()
        for lang, block in re.findall(r"```(\w*)\n(.*?)```", text, re.S):
            if lang not in ("", "sh", "bash", "console"):
                continue
            for line in block.replace("\\\n", " ").splitlines():
                line = line.strip().removeprefix("uv run ")
                if re.match(r"wott-hub (devices (list|health)|directory (query|list))\b", line) \
                        or (line.startswith("curl ") and "127.0.0.1:8080" in line and " -N " not in line):
                    found.append((path.name, line))
        for span in re.findall(r"`(wott-hub directory query '[^`]*')\s*\n?\[--url URL\]`", text):
            found.append((path.name, span))
    return found


def test_every_example_of_the_docs_that_runs_against_the_demo_answers(demo):
    examples = _doc_examples()
    names = {line.split()[0] + " " + line.split()[1] for _, line in examples}
    assert {"wott-hub devices", "wott-hub directory", "curl -s"} <= names, examples
    for doc, line in examples:
        line = re.sub(r"\s+#.*$", "", line)  # a trailing comment
        line = re.sub(r" \[[A-Z][A-Z_ ]*\]", "", line)  # an optional argument ([ID])
        args = shlex.split(line.replace("http://127.0.0.1:8080", demo.http))
        if args[0] == "wott-hub":
            args[0] = str(Path(sys.executable).with_name("wott-hub"))
        res = subprocess.run(args, capture_output=True, text=True, timeout=120,
                             env={**os.environ, **_env(demo), "COLUMNS": "80"})
        assert res.returncode == 0, (doc, line, res.stderr)
        assert res.stdout.strip() not in ("", "[]"), (doc, line, res.stdout)


def _recorded(database: str) -> set[str]:
    """The devices with a record in ``database`` so far, read in this process: waiting by polling
    the command would start a Python process (~0.8 s of CPU) every poll; the tests assert on what the
    command prints once the wait is over."""
    from sqlalchemy.exc import OperationalError

    from wott_hub.cli._db import open_reader
    from wott_hub.errors import HistoryError

    try:
        reader = open_reader(database, integrity=False)
    except (HistoryError, OperationalError):  # not made yet: no file, no tables, the file locked
        return set()
    try:
        return {t.id for t in reader.things(count=False) if t.first_seq is not None}
    finally:
        reader.engine.dispose()


def test_history_list_of_the_demo_at_80_columns(cli, demo, eventually):
    # every device's first batch written (a loaded machine writes late)
    eventually(lambda: DEMO <= _recorded(demo.database), timeout=120, what="a row for every demo device")
    res = cli("history", "list", "--database", demo.database)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == f"history: {demo.database}"  # a path: whole, however long
    assert re.match(r"^device +family +from \(UTC[+-]\d\d:\d\d\) +to", lines[1]), lines[1]
    assert all(len(line) <= 80 for line in lines[1:])
    for did in DEMO:
        row = re.search(rf"^{did} .*$", res.stdout, re.M)
        assert row is not None, res.stdout
        times = re.findall(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d{3}", row.group())
        assert len(times) == 2, row.group()  # both whole
    listed = json.loads(cli("history", "list", "--database", demo.database, "--json", "--count").stdout)
    assert {t["id"] for t in listed} >= DEMO
    assert all(t["count"] >= 1 and t["last_seq"] >= t["first_seq"] for t in listed)


def test_history_audit_says_why_it_is_empty_and_lists_a_write(cli, demo, eventually):
    since = str(time.time())
    res = cli("history", "audit", "--database", demo.database, "--from", since, "--who", "nobody")
    assert res.returncode == 0 and res.stdout == ""
    assert res.stderr.startswith(f"no audited request by 'nobody' since {since} in {demo.database}: "
                                 "the trail "
                                 "holds writes, actions and refused credentials; reads")
    res = cli("devices", "restart", "taxel-1", env=_env(demo))
    assert res.returncode == 0, res.stderr

    def audited() -> bool:  # read in this process (see _recorded); the command is asserted on below
        from sqlalchemy.exc import OperationalError

        from wott_hub.history import create_engine, database_url
        from wott_hub.security import read_audit

        engine = create_engine(database_url(demo.database))
        try:
            entries = read_audit(engine, limit=1000, since_ns=int(float(since) * 1e9))
        except OperationalError:  # the file locked by a write: again at the next poll
            return False
        finally:
            engine.dispose()
        return any((e.action, e.target) == ("POST", "/wot/hub/actions/restartDevice") for e in entries)

    eventually(audited, timeout=60, what="the restart in the audit trail")
    out = cli("history", "audit", "--database", demo.database, "--from", since).stdout
    assert "POST    /wot/hub/actions/restartDevice" in out, out


def test_td_validate_a_served_td_by_url_and_from_stdin(cli, demo):
    url = demo.devices["barrel-1"]
    res = cli("td", "validate", url)
    assert res.returncode == 0 and res.stdout.strip() == f"{url}: valid", res.stdout + res.stderr
    res = cli("td", "validate", "-", input=httpx.get(url, timeout=30).text)
    assert res.returncode == 0 and res.stdout.strip() == "-: valid"
    res = cli("td", "validate", f"{demo.http}/wot/nothing-here")
    assert res.returncode == 3 and "no TD there (HTTP 404)" in res.stderr


def test_discover_at_80_columns_keeps_whole_urls(cli, demo):
    def listed(out: str) -> bool:  # the demo's (other hubs may announce on loopback too)
        return all(re.search(rf"^\S+\s+{re.escape(demo.devices[d])}(\s|$)", out, re.M) for d in DEMO)

    for _ in range(4):  # again if a loaded machine (another worker's mDNS too) missed one in the window
        res = cli("discover", "--interface", "127.0.0.1", "--timeout", "10", timeout=120)
        assert res.returncode == 0, res.stderr
        if listed(res.stdout):
            break
    assert listed(res.stdout), res.stdout
