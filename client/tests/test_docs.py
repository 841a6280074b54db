"""docs/client.md's example, run as written against a live hub (the demo's device and the doc's URL
swapped for the test hub's), so that the documentation cannot rot."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import httpx

DOC = Path(__file__).resolve().parents[2] / "docs" / "client.md"


def _example() -> str:
    text = DOC.read_text()
    marker = text.index("<!-- example:")
    return re.search(r"```python\n(.*?)```", text[marker:], re.S).group(1)


def test_the_documented_example_runs_against_a_live_hub(hub, tmp_path):
    code = _example()
    assert 'HUB = "http://127.0.0.1:8080"' in code and "/wot/flatpad-1" in code
    script = tmp_path / "example.py"
    script.write_text(code.replace("http://127.0.0.1:8080", hub.url).replace("/wot/flatpad-1", "/wot/pad"))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    pad, cyl = (httpx.get(f"{hub.url}/wot/{d}").json()["id"] for d in ("pad", "cyl"))
    assert lines[0].startswith(f"{pad} (256, 3) (")
    assert sum(" peak " in line for line in lines) == 10
    assert f"following {sorted([pad, cyl])}" in lines
    assert lines[-1].startswith(f"last Frame(thing='{pad}'")
