"""PyPI's ``flexitac`` 0.3.1 judges the hub's FlexiTac reading: the same bytes on two pty pairs, read by
its ``FlexiTacSensor`` and by the hub's serial reader, give the same frames value for value, the same
baseline (the median of 30 frames) and the same baseline-subtracted counts."""

from __future__ import annotations

import asyncio
import threading

import numpy as np
from flexitac import FlexiTacSensor
from wott_driver_taxel.pty_port import PtyPort
from wott_driver_taxel.reader import SerialReader
from wott_driver_taxel.readings import CountReadings

ROWS, COLS = 12, 32
BASELINE, MORE = 30, 40


def frame(k: int, rng: np.random.Generator) -> np.ndarray:
    v = rng.integers(15, 40, (ROWS, COLS))
    if k >= BASELINE + 10:
        v[4:7, 10:14] += 120  # a press after the baseline
    if k % 4 == 0:
        v.flat[k % 300], v.flat[k % 300 + 1] = 0xAA, 0x55  # the marker inside the payload
    return v


def test_flexitac_and_the_hub_read_the_same_frames(tmp_path, until):
    rng = np.random.default_rng(12)
    sent = [frame(k, rng) for k in range(BASELINE + MORE)]
    data = b"".join(b"\xaa\x55" + v.astype(np.uint8).tobytes() for v in sent) + b"\xaa\x55"
    theirs, hub = PtyPort(tmp_path / "theirs"), PtyPort(tmp_path / "hub")
    their_path, hub_path = theirs.open(), hub.open()
    result: dict[str, object] = {}
    opened = threading.Event()

    def their_side() -> None:
        with FlexiTacSensor(their_path, rows=ROWS, cols=COLS) as sensor:
            opened.set()
            result["baseline"] = sensor.calibrate()
            result["frames"] = [sensor.read() for _ in range(MORE)]

    async def main():
        reader = SerialReader(hub_path, shape=(ROWS, COLS), protocol="flexitac", baudrate=2_000_000)
        got = []

        async def consume():
            async for _, f in reader.frames():
                got.append(f)

        task = asyncio.create_task(consume())
        await until(lambda: reader.connected, "the hub's port")
        maker = threading.Thread(target=their_side)
        maker.start()
        await asyncio.to_thread(opened.wait, 20)
        await asyncio.gather(*(asyncio.to_thread(p.write_all, data) for p in (theirs, hub)))
        await until(lambda: len(got) == len(sent), "every frame")
        await asyncio.to_thread(maker.join, 20)
        await reader.close()
        await asyncio.wait_for(task, 5)
        return got, reader.counters

    got, counters = asyncio.run(main())
    theirs.close()
    hub.close()
    assert counters.frames == len(sent) and counters.resyncs == counters.truncated == 0
    readings = CountReadings(np.tile([0.0, 0.0, -1.0], (ROWS * COLS, 1)), (ROWS, COLS), 0.0, BASELINE)
    changes = [readings.frame(k, f.values) for k, f in enumerate(got)]
    assert changes[BASELINE - 2] is None and changes[BASELINE - 1] is not None
    np.testing.assert_array_equal(readings.baseline.reshape(ROWS, COLS), result["baseline"])
    their_frames = result["frames"]
    assert isinstance(their_frames, list) and len(their_frames) == MORE
    for k, t in enumerate(their_frames, start=BASELINE):
        np.testing.assert_array_equal(got[k].values.reshape(ROWS, COLS), t.raw)
        np.testing.assert_array_equal(got[k].values.reshape(ROWS, COLS), sent[k])
    last = readings.raw_sample("change")
    assert last is not None
    np.testing.assert_array_equal(last.array, their_frames[-1].raw.astype(np.float64) - result["baseline"])
    assert last.array[5, 11] > 100  # the press, above the baseline
