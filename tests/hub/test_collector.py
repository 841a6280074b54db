"""``wott-hub run`` sets the collector for a hub (``hub.collector``): the thresholds, and what
start-up made frozen; a program that embeds ``Hub`` keeps its own. In a process of its own (the
settings are the process's)."""

from __future__ import annotations

import json
import subprocess
import sys

SCRIPT = r"""
import asyncio, gc, json, sys
from wott_hub.config import HubConfig
from wott_hub.hub import Hub, serve

async def main():
    before = list(gc.get_threshold())
    cfg = HubConfig(http_port=0, ws_port=None, history=False)
    async with Hub(cfg):
        embedded = (list(gc.get_threshold()), gc.get_freeze_count())
    stop, seen = asyncio.Event(), {}

    def ready(hub):
        seen["served"] = (list(gc.get_threshold()), gc.get_freeze_count())
        stop.set()

    await serve(cfg, ready=ready, stop=stop, exit_s=None)
    print(json.dumps({"before": before, "embedded": embedded, **seen}))

asyncio.run(main())
"""


def test_serve_tunes_the_collector_and_an_embedded_hub_does_not(tmp_path):
    from wott_hub.hub.collector import THRESHOLDS

    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    threshold, frozen = got["embedded"]
    assert threshold == got["before"] and frozen == 0  # the process's own settings, untouched
    threshold, frozen = got["served"]
    assert tuple(threshold) == THRESHOLDS and frozen > 10_000  # start-up's objects out of sight
