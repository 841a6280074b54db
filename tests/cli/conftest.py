"""The ``wott-hub`` command as a person runs it: a real process, output not a terminal, 80 columns.

``cli(*args)`` (tests/conftest.py) runs the installed ``wott-hub`` with ``COLUMNS=80`` (what a pipe
or a CI log gets) and returns the finished process. ``demo`` is a real ``wott-hub run`` with no
config (the demo fleet, free ports, its database in a temporary folder), started once for the module that
uses it and stopped with SIGINT at its end (a session-scoped one kept the fleet simulating, ~0.4 of a
core, until its worker's last test); it yields what its banner printed, parsed: the URLs are read from the
banner, so a banner that cuts or loses one fails every test that needs it.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

WOTT_HUB = str(Path(sys.executable).with_name("wott-hub"))


@dataclass
class Demo:
    folder: Path
    banner: list[str]
    http: str = ""
    hub: str = ""
    directory: str = ""
    database: str = ""
    devices: dict[str, str] = field(default_factory=dict)
    curl: str = ""


def _parse(folder: Path, lines: list[str]) -> Demo:
    demo = Demo(folder, lines)
    for line in lines:
        words = line.split()
        if line.startswith("  HTTP "):
            demo.http = words[1]
        elif line.startswith("  hub Thing "):
            demo.hub = words[2]
        elif line.startswith("  directory "):
            demo.directory = words[1]
        elif line.startswith("  history ") and words[1] != "off":
            demo.database = words[1]
        elif re.match(r"^    \S+\s+\S+\s+https?://", line):
            demo.devices[words[0]] = words[2]
        elif line.strip().startswith("curl "):
            demo.curl = line.strip()
    return demo


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """A real demo hub (``wott-hub run``, free ports) for the module, its banner parsed."""
    folder = tmp_path_factory.mktemp("demo")
    env = {**os.environ, "COLUMNS": "80"}
    log = (folder / "hub.log").open("w")  # a pipe nobody reads could fill and block the hub's logging
    proc = subprocess.Popen([WOTT_HUB, "run", "--port", "0", "--ws-port", "0"], cwd=folder, env=env,
                            stdout=subprocess.PIPE, stderr=log, text=True)
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line.rstrip("\n"))
            if line.startswith("ready in "):
                break
        assert lines and lines[-1].startswith("ready in "), (lines, proc.poll())
        yield _parse(folder, lines)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)
        log.close()
