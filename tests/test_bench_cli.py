"""``wott-hub bench``: finds the benchmarks in the checkout (scripts and packages) and rejects bad options
with one line and exit code 2, before any measurement starts.

No benchmark is run here: the smallest hub group takes far longer than a test may on the shared
machine (see docs/benchmarks.md for how to run one).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([WOTT_HUB, "bench", *args], cwd=ROOT, capture_output=True, text=True, timeout=60)


def test_lists_script_and_package_benchmarks():
    res = _bench()
    assert res.returncode == 0, res.stderr
    names = res.stdout.split()
    assert "hub" in names  # the package benchmarks/bench_hub/
    assert "directory" in names  # a script, benchmarks/bench_directory.py


@pytest.mark.parametrize(("args", "message"), [
    (["--groups", "latency,nope"], "unknown group nope"),
    (["--devices", "0"], "--devices"),
    (["--devices", "eight"], "--devices"),
    (["--duration", "-1"], "--duration"),
    (["--workers", "0"], "--workers"),
    (["--workers", "one"], "--workers"),
    (["--workers", "65"], "--workers"),
])
def test_hub_bad_option_is_one_line_and_exit_2(args, message):
    res = _bench("hub", *args, "--no-write")
    assert res.returncode == 2
    assert message in res.stderr
    assert "Traceback" not in res.stderr
    assert not res.stdout  # stopped before any group started


def test_unknown_benchmark_names_the_available_ones():
    res = _bench("nope")
    assert res.returncode == 2
    assert "unknown benchmark 'nope'" in res.stderr and "hub" in res.stderr


def test_hub_help_offers_the_64_device_point_and_worker_variants():
    res = _bench("hub", "--", "--help")  # after `--`: the benchmark's own help, not the CLI's
    assert res.returncode == 0, res.stderr
    assert "1,8,32,64" in res.stdout  # the 64 x 120 Hz point is in the default latency points
    assert "--workers" in res.stdout and "--devices" in res.stdout


def test_a_run_of_some_hub_groups_keeps_the_other_groups_tables(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    from bench_hub import report

    doc = tmp_path / "benchmarks.md"
    doc.write_text("# Benchmarks\n\n<!-- bench:hub -->\n## Hub\n\nRun: `old` · 2026-11-22\n\nLoad 1.\n\n"
                   "### Latency: old (ms)\n\nL1\n\n### Start-up of the demo scene\n\nS1\n\n"
                   "### History\n\nH1\n\n(Not re-run: kept from `older`.)\n<!-- /bench:hub -->\n")
    monkeypatch.setattr(report, "DOC", doc)
    text = report.keep_others("Load 2.\n\n### Start-up of the demo scene\n\nS2")
    assert "S2" in text and "S1" not in text  # the group re-run replaces its table
    assert "### Latency: old (ms)\n\nL1\n\n(Not re-run: kept from `old` · 2026-11-22.)" in text
    assert text.count("(Not re-run") == 2 and "kept from `older`" in text  # an older note stays as it was


@pytest.mark.parametrize(("args", "message"), [
    (["/nonexistent"], "not a wott-hub checkout"),
    ([str(ROOT), "--rounds", "0"], "--rounds"),
    ([str(ROOT), "--duration", "0"], "--duration"),
    ([], "DIR"),
])
def test_alternate_bad_options_are_one_line_and_exit_2(args, message):
    res = _bench("alternate", *args)
    assert res.returncode == 2
    assert message in res.stderr.splitlines()[-1]
    assert "Traceback" not in res.stderr and not res.stdout  # nothing measured


def test_alternate_latency_of_due_frames_counts_an_undelivered_frame_as_later_than_any(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    from bench_alternate import _RUN, of_due

    lat = [float(v) for v in range(100, 0, -1)]  # 1..100, in any order
    assert of_due(lat, 100, 99) == 99.0 and of_due(lat, 100, 95) == 95.0  # all delivered: nearest rank
    assert of_due(lat[4:], 100, 95) == 95.0  # the 4 latest never delivered: p95 is still a delivered one
    assert of_due(lat[2:], 100, 99) == float("inf")  # 2 % never delivered: no p99 is reached
    assert of_due([], 10, 50) == float("inf")
    assert "def of_due(" in _RUN  # the copy the run in another checkout uses
    compile(_RUN, "bench_alternate._RUN", "exec")
