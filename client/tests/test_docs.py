"""docs/client.md's example, run as written against a live hub (the demo's device and the doc's URL
swapped for the test hub's), so that the documentation cannot rot."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import httpx

DOC = Path(__file__).resolve().parents[2] / "docs" / "client.md"


def _example(marker: str = "<!-- example:") -> str:
    text = DOC.read_text()
    return re.search(r"```python\n(.*?)```", text[text.index(marker):], re.S).group(1)


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


def test_the_documented_issue_29_example_runs_against_a_live_hub(recorded, tmp_path, eventually):
    """Displacement fields, raw frames, actions and history ranges, as docs/client.md shows them (the
    demo's camera pad and taxel array swapped for the test hub's ``cam`` and ``grid``)."""
    code = _example("<!-- example-29:")
    names = {"/wot/flatpad-1": "/wot/cam", "/wot/taxel-1": "/wot/grid", '"flatpad-1"': '"cam"'}
    for doc, test in names.items():
        assert doc in code
        code = code.replace(doc, test)
    script = tmp_path / "example29.py"
    script.write_text(code.replace("http://127.0.0.1:8080", recorded.url))
    hub_form = httpx.get(f"{recorded.url}/wot/hub").json()["actions"]["historyRecords"]["forms"][0]["href"]
    eventually(lambda: httpx.post(hub_form, json={"device": "cam", "names": ["skinDisplacement"], "limit": 1,
                                                  "from": "-1m"}).text.strip(),
               timeout=90, what="the camera pad's first recorded skinDisplacement")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[:3] == ["image (480, 640, 1) ['camera']", "grid (16, 16)", "ok"]
    assert lines[3].startswith("history ") and lines[3].endswith(", 256, 3)")
