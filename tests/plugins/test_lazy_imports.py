"""What a device costs before its TD can be served (checked in a fresh process).

A hub whose devices have no cameras never imports cv2 or onnxruntime; a camera skin
imports OpenCV and SciPy (and builds its detectors, trackers, depth solver) only when its
frames start, in its worker thread, not when it is opened: the hub serves every TD
first (docs/hub.md, "Start-up and bytecode")."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

SCRIPT = r'''
import asyncio, json, sys
from wott_hub.plugins import DeviceConfig, get_registry

async def main():
    registry = get_registry()
    registry.plugins()
    registry.demo_devices()
    devices = [
        registry.open_device(DeviceConfig("taxel", "taxel-array", {"simulate": True, "rate_hz": 200})),
        registry.open_device(DeviceConfig("bench", "scene", {
            "step": [{"kind": "press", "at": [10.0, 10.0, 0.0], "depth_mm": 1.0}], "realtime": False})),
    ]
    counts = []
    for d in devices:
        n = 0
        async for _ in d.frames():
            n += 1
            if n == 5:
                break
        await d.close()
        counts.append(n)
    return counts

counts = asyncio.run(main())
print(json.dumps({"frames": counts, "loaded": [m for m in ("cv2", "onnxruntime") if m in sys.modules],
                  "plugins": sorted(p.name for p in get_registry().plugins())}))
'''


@pytest.mark.parametrize("selection", ["taxel", None], ids=["taxel-only", "all-installed-plugins"])
def test_taxel_and_scene_devices_import_neither_cv2_nor_onnxruntime(selection):
    env = {k: v for k, v in os.environ.items() if k != "WOTT_HUB_PLUGINS"}
    if selection is not None:
        env["WOTT_HUB_PLUGINS"] = selection
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["frames"] == [5, 5]
    assert result["loaded"] == [], f"imported {result['loaded']} with plugins {result['plugins']}"


CAMERA_SCRIPT = r"""
import asyncio, json, sys
from wott_hub.plugins import DeviceConfig, get_registry

HEAVY = ("cv2", "scipy.sparse", "scipy.spatial")

async def main():
    registry = get_registry()
    devices = [registry.open_device(DeviceConfig("barrel", "barrel-vision", {})),
               registry.open_device(DeviceConfig("pad", "flat-vision", {}))]
    opened = [m for m in HEAVY if m in sys.modules]
    for d in devices:
        async for _ in d.frames():
            break
        await d.close()
    return {"opened": opened, "running": [m for m in HEAVY if m in sys.modules]}

print(json.dumps(asyncio.run(main())))
"""


def test_camera_skins_import_opencv_and_scipy_when_their_frames_start_not_when_opened():
    out = subprocess.run([sys.executable, "-c", CAMERA_SCRIPT], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"opened": [], "running": ["cv2", "scipy.sparse", "scipy.spatial"]}
