from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

import pytest

SIM = Path(__file__).with_name("wot_device_sim.py")
WOTT_HUB = Path(sys.executable).with_name("wott-hub")


class Sim:
    """The WoT device simulator (wot_device_sim.py) in its own process: ``url`` is its TD's URL,
    ``base`` the URL its TD's forms and control endpoints are relative to."""

    def __init__(self, host: str, name: str = "skin-7", thing_id: str = "urn:example:wot-skin-7") -> None:
        self.proc: asyncio.subprocess.Process | None = None
        self.args = [sys.executable, str(SIM), "--host", host, "--name", name, "--id", thing_id]
        self.url = ""

    @property
    def base(self) -> str:
        return self.url.removesuffix("td")

    async def start(self) -> Sim:
        self.proc = await asyncio.create_subprocess_exec(*self.args, stdout=asyncio.subprocess.PIPE)
        line = (await asyncio.wait_for(self.proc.stdout.readline(), 30)).decode()
        assert line.startswith("READY "), line
        self.url = line.split()[1]
        return self

    async def stop(self) -> None:
        if self.proc is not None and self.proc.returncode is None:
            self.proc.terminate()
            await asyncio.wait_for(self.proc.wait(), 15)


@pytest.fixture(scope="session")
def device_sim():
    """The Sim class: ``sim = await device_sim("127.0.0.1").start()`` ... ``await sim.stop()`` (in the
    test's own event loop, which owns the subprocess)."""
    return Sim


async def _discover(names: set[str], window_s: int, browses: int = 5) -> dict[str, dict]:
    """What ``wott-hub discover --json`` lists on 127.0.0.1, run in another process (the real command),
    by name: browsed again, ``browses`` times at most, until every one of ``names`` is listed (a
    loaded machine, another worker's mDNS traffic too, can miss one in a ``window_s`` window). The
    last browse's rows: the test asserts what it needs of them."""
    rows: dict[str, dict] = {}
    for _ in range(browses):
        proc = await asyncio.create_subprocess_exec(
            str(WOTT_HUB), "discover", "--interface", "127.0.0.1", "--timeout", str(window_s), "--json",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
        out, err = await asyncio.wait_for(proc.communicate(), 60)
        assert proc.returncode == 0, err.decode()
        rows = {r["name"]: r for r in json.loads(out)}
        if names <= rows.keys():
            break
    return rows


@pytest.fixture(scope="session")
def discover():
    """``rows = await discover(names, window_s)``: see ``_discover`` (in the test's own event loop)."""
    return _discover
