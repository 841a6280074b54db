"""A hub without ``[foxglove]`` that exports nothing never loads foxglove-sdk or rosbags (checked in a
fresh process), and ``wott-hub --help`` loads neither."""

from __future__ import annotations

import json
import subprocess
import sys

SCRIPT = r"""
import asyncio, json, sys
from wott_hub.config import HubConfig
from wott_hub.hub import Hub

async def main():
    cfg = HubConfig(http_port=0, ws_port=None, history=False)
    async with Hub(cfg) as hub:
        hub.describe()
asyncio.run(main())
import wott_hub.cli
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in ("foxglove", "rosbags", "mcap_ros2"))))
"""


def test_a_hub_without_foxglove_loads_neither_sdk():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
