"""``wott-hub bench client`` is found and rejects bad options with one clear line (no benchmark is run:
the shared machine has no room for one inside the suite)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
WOTT_HUB = str(Path(sys.executable).parent / "wott-hub")


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([WOTT_HUB, "bench", *args], capture_output=True, text=True, cwd=ROOT, timeout=120)


def test_the_client_benchmark_is_listed():
    assert "client" in _bench().stdout.split()


def test_bad_options_are_refused_in_one_line():
    for bad in (["--rate", "0"], ["--devices", "0"], ["--hz", "-1"], ["--seconds", "0"]):
        res = _bench("client", *bad)
        assert res.returncode == 2, bad
        assert "must be positive" in res.stderr and "Traceback" not in res.stderr
