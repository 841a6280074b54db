"""wott-client stays light: it declares numpy and httpx only (zeroconf as the ``mdns`` extra), and
importing it loads neither the hub nor wotpy, SciPy, OpenCV or zeroconf."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_declared_dependencies_are_numpy_and_httpx():
    project = tomllib.loads(PYPROJECT.read_text())["project"]
    names = sorted(d.split(">")[0].split("=")[0].strip() for d in project["dependencies"])
    assert names == ["httpx", "numpy"]
    assert [d.split(">")[0] for d in project["optional-dependencies"]["mdns"]] == ["zeroconf"]


def test_importing_the_client_loads_nothing_heavy():
    code = ("import sys, wott_client\n"
            "heavy = ('wott_hub', 'wotpy', 'scipy', 'cv2', 'zeroconf', 'tornado', 'jsonschema')\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[]"
