"""Shared fixtures: where the read-only reference data lives, and scene playback."""

from __future__ import annotations

import asyncio
import inspect
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.exists():
        pytest.fail(f"reference data not found at {SHARED_DATA} (../shared beside the checkout)")
    return SHARED_DATA


async def _wait_for(predicate, timeout: float = 15.0, what: str = "condition", every: float = 0.05) -> None:
    """Poll ``predicate`` (sync or async) until true; fail naming ``what`` after ``timeout`` s."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        ok = predicate()
        if inspect.isawaitable(ok):
            ok = await ok
        if ok:
            return
        if loop.time() > deadline:
            raise AssertionError(f"{what}: not met within {timeout} s")
        await asyncio.sleep(every)


@pytest.fixture(scope="session")
def wait_for():
    """``await wait_for(predicate, timeout=..., what=...)`` inside a test's event loop."""
    return _wait_for
