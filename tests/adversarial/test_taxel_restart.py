"""Issue 16 item 3: the taxel driver restarts after any exception, and health keeps the cause.

A real pty pair stands in for the board. An absurd (but finite) ``kpa_per_count``
turns one large reading into an infinite pressure, which the ``TactileFrame``
check refuses: the exception leaves ``frames()`` as it would reach the hub,
which then calls ``frames()`` again, exactly as the hub's pipeline does.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from wott_driver_taxel.compliance import Compliance
from wott_driver_taxel.driver import TaxelDriver
from wott_driver_taxel.plugin import open_taxel_device
from wott_driver_taxel.protocol import encode_frame
from wott_driver_taxel.pty_port import PtyPort

from wott_hub.drivers.backoff import Backoff
from wott_hub.drivers.base import Health
from wott_hub.plugins import DeviceConfig
from wott_hub.tactile import FrameError

SHAPE = (4, 4)


def frame(seq: int, value: int) -> bytes:
    return encode_frame(seq, np.full(SHAPE, value))


async def until(condition, what: str, timeout_s: float = 10.0) -> None:
    deadline = asyncio.get_running_loop().time() + timeout_s
    while not condition():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.005)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_frames_restarts_after_an_exception_and_health_names_the_cause(tmp_path):
    port = PtyPort(tmp_path / "ttyTAXEL")
    port.open()
    described = open_taxel_device(DeviceConfig("t", "taxel-array", {"port": port.path, "rows": 4, "cols": 4}))
    driver = TaxelDriver(described.description, shape=SHAPE, compliance=Compliance(69.0, 3.0, 1e306),
                         port=port.path, backoff=Backoff(initial_s=0.01, cap_s=0.05))

    def reason() -> str:
        return driver.health().reason

    async def main() -> None:
        for attempt in range(3):  # fail, restart, fail again: every restart gets a working port
            stream = driver.frames()
            first = asyncio.ensure_future(anext(stream))
            await until(lambda: "waiting for frames" in reason(), f"the port to open (attempt {attempt})")
            if attempt:
                assert "(restarted after FrameError: pressure has NaN/Inf values)" in reason()
            await asyncio.to_thread(port.write_all, frame(0, 10))
            good = await asyncio.wait_for(first, 5)
            assert np.isfinite(good.pressure).all() and driver.last_seq == 0
            await until(lambda: driver.health().state == Health.ok, "health ok after a good frame")
            assert "restarted" not in reason()
            await asyncio.to_thread(port.write_all, frame(1, 1000))  # 1000 * 1e306 kPa: inf
            with pytest.raises(FrameError):
                await asyncio.wait_for(anext(stream), 5)
            assert driver.health().state == Health.disconnected
            assert reason() == "frames() failed: FrameError: pressure has NaN/Inf values"
        # a stream abandoned without being closed does not hold the port either
        abandoned = driver.frames()
        pending = asyncio.ensure_future(anext(abandoned))
        await until(lambda: "waiting for frames" in reason(), "the port to open for the abandoned stream")
        await asyncio.to_thread(port.write_all, frame(2, 10))
        assert (await asyncio.wait_for(pending, 5)) is not None and driver.last_seq == 2
        stream = driver.frames()
        pending = asyncio.ensure_future(anext(stream))
        await until(lambda: "waiting for frames" in reason(), "the port to reopen")
        await asyncio.to_thread(port.write_all, frame(3, 10))
        assert (await asyncio.wait_for(pending, 5)) is not None and driver.last_seq == 3
        assert "already being iterated" not in reason()
        await stream.aclose()
        await driver.close()
        assert driver.health().state == Health.disconnected and reason() == "closed"

    asyncio.run(main())
    port.close()
