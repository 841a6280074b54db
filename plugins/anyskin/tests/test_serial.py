"""An AnySkin board on a real pty: garbage and split writes mid-stream, repeats, an unplugged port (EIO)
that marks the device disconnected and comes back, and the simulated board pressed."""

from __future__ import annotations

import asyncio

import numpy as np
from wott_driver_anyskin.protocol import FRAME_SIZE, encode_sample
from wott_driver_anyskin.simulator import AnySkinSimulator
from wott_driver_taxel.pty_port import PtyPort

from wott_hub.plugin_api import Health
from wott_hub.plugins import DeviceConfig, Registry

REGISTRY = Registry(only=["anyskin"])


def frames(start: int, n: int) -> list[bytes]:
    rng = np.random.default_rng(start)
    return [encode_sample(np.full(5, 25.0), rng.normal(0, 300, (5, 3))) for _ in range(n)]


class Run:
    """The driver on ``path``, its frames collected by a task."""

    def __init__(self, path: str, until, **settings) -> None:
        self.until = until
        self.driver = REGISTRY.open_device(DeviceConfig("skin", "anyskin", {
            "port": path, "backoff_initial_s": 0.02, "backoff_cap_s": 0.1, **settings}))
        self.frames: list = []
        self.health: list[tuple[Health, str]] = []

    async def __aenter__(self) -> Run:
        async def consume():
            async for f in self.driver.frames():
                self.frames.append(f)

        async def watch():
            while True:
                h = self.driver.health()
                if not self.health or self.health[-1] != (h.state, h.reason):
                    self.health.append((h.state, h.reason))
                await asyncio.sleep(0.005)

        self.tasks = [asyncio.create_task(consume()), asyncio.create_task(watch())]
        await self.until(lambda: "waiting for frames" in self.driver.health().reason, "the port to open")
        return self

    async def __aexit__(self, *exc) -> None:
        await self.driver.close()
        for t in self.tasks:
            t.cancel()
        await asyncio.gather(*self.tasks, return_exceptions=True)


def test_garbage_and_odd_writes_mid_stream_lose_at_most_the_frame_they_hit(tmp_path, until):
    port = PtyPort(tmp_path / "ttyACM0")
    path = port.open()
    good = frames(1, 60)
    junk = np.random.default_rng(2).integers(0, 256, 1024, dtype=np.uint8).tobytes()
    cut = 25 * FRAME_SIZE + 40  # inside frame 25
    data = b"".join(good)
    data = data[:cut] + junk + data[cut:]

    async def main():
        async with Run(path, until, baseline_samples=1) as run:
            for i in range(0, len(data), 113):  # writes of any size, across frame boundaries
                await asyncio.to_thread(port.write_all, data[i : i + 113])
            c = run.driver.counters
            await until(lambda: c.frames >= 59, "the frames after the garbage")
            await asyncio.sleep(0.2)
            assert c.frames == 59 and c.resyncs == 1 and c.garbage_bytes == 1024 + FRAME_SIZE
            assert len(run.frames) == 59  # the first is the baseline's and a frame too
            degraded = [r for s, r in run.health if s == Health.degraded and r.startswith("link errors")]
            assert degraded and "1 resyncs" in degraded[-1]

    asyncio.run(main())
    port.close()


def test_an_unplugged_board_is_disconnected_and_comes_back(tmp_path, until):
    port = PtyPort(tmp_path / "ttyACM0")
    path = port.open()

    async def main():
        # the "lost" state lasts one back-off (then "cannot open"): 0.3 s, for the watcher polling every
        # 5 ms on a loop that a loaded machine may not run for tens of ms
        async with Run(path, until, baseline_samples=2, backoff_initial_s=0.3, backoff_cap_s=0.3) as run:
            await asyncio.to_thread(port.write_all, b"".join(frames(3, 10)))
            await until(lambda: len(run.frames) == 9, "the first frames")
            port.unplug()  # the pty goes: the reader's next read fails (EIO), the path vanishes
            await until(lambda: run.driver.health().state == Health.disconnected, "disconnected")
            await until(lambda: run.driver.health().reason.startswith("cannot open"), "failed re-opens")
            assert any(s == Health.disconnected and r.startswith(f"lost {path}") for s, r in run.health)
            port.replug()
            await until(lambda: run.driver.counters.reconnects == 1, "the re-open")
            await asyncio.sleep(0.05)
            await asyncio.to_thread(port.write_all, b"".join(frames(4, 10)))
            await until(lambda: len(run.frames) == 19, "frames after the replug")
            await until(lambda: run.driver.health().state == Health.ok, "ok again")

    asyncio.run(main())
    port.close()


def test_repeats_are_skipped_and_said_in_health(tmp_path, until):
    port = PtyPort(tmp_path / "ttyACM0")
    path = port.open()
    good = frames(5, 8)
    data = b"".join(f for f in good for _ in range(2))  # every sample sent twice, as a fast loop does

    async def main():
        async with Run(path, until, baseline_samples=1) as run:
            await asyncio.to_thread(port.write_all, data)
            await until(lambda: len(run.frames) == 8, "the samples")
            assert run.driver.counters.duplicates == 8
            await until(lambda: run.driver.health().state == Health.ok, "ok")
            assert run.driver.health().reason == "50 % of samples were repeats of the one before (skipped)"

    asyncio.run(main())
    port.close()


def test_a_press_on_the_simulated_board_shows_where_it_was_pressed():
    driver = REGISTRY.open_device(DeviceConfig("skin", "anyskin", {"simulate": True, "rate_hz": 200.0}))
    sim: AnySkinSimulator = driver.simulator
    right = driver.board.places.index("right")

    async def main():
        out = []
        async for f in driver.frames():
            out.append(f)
            if len(out) == 20:
                sim.press(right, 500.0)
            if len(out) == 60:
                break
        await driver.close()
        return out

    out = asyncio.run(main())
    change = out[-1].displacement
    assert change[right, 2] < -450 and np.abs(change[right, :2]).max() < 10  # into the board, at that chip
    assert np.abs(out[10].displacement).max() < 10  # at rest: noise only
    tm = driver.raw_sample("raw")
    assert tm is not None and tm.array.shape == (5, 3)
