"""The makers' readers judge the hub's: the same bytes, written to pty pairs, are read by PyPI's
``anyskin`` 1.0.0 (``AnySkinBase``) or ``reskin-sensor`` 2.0.2 (``ReSkinBase``) and by the hub, and
the numbers agree sample for sample, exactly (payloads holding ``\\r\\n`` included); the hub's frames
are the board-frame changes of those very numbers."""

from __future__ import annotations

import asyncio
import struct
import threading

import numpy as np
import pytest
from anyskin import AnySkinBase
from reskin_sensor import ReSkinBase
from wott_driver_anyskin.boards import BOARDS
from wott_driver_anyskin.protocol import AnySkinDecoder
from wott_driver_taxel.pty_port import PtyPort
from wott_driver_taxel.reader import SerialReader

from wott_hub.plugins import DeviceConfig, Registry

# The makers' readers empty their input when more than 4000 bytes wait, and read a frame only once more
# than 82 bytes wait: 45 frames (3690 bytes) written at once, the last never read by them.
N = 45
CRLF = struct.unpack("<f", b"\r\n\x41\x43")[0]


def board_values(k: int, rng: np.random.Generator) -> np.ndarray:
    """(5, 4) float32 of frame ``k``: temperature, then x, y, z µT, as each chip reads them."""
    v = np.column_stack([25.0 + rng.normal(0, 0.1, 5), rng.normal(0, 400, (5, 3))]).astype(np.float32)
    if k % 3 == 1:
        v[k % 5, 1 + k % 3] = CRLF  # a "\r\n" inside the payload
    return v


def makers_reader(board: str, path: str):
    if board == "anyskin":
        sensor = AnySkinBase(num_mags=5, port=path, temp_filtered=False)
        return sensor, lambda: sensor.get_sample()[1]
    sensor = ReSkinBase(num_mags=5, port=path, temp_filtered=False, reskin_data_struct=False)
    return sensor, lambda: sensor.get_sample()[2]


@pytest.mark.parametrize("board", ["anyskin", "reskin"])
def test_the_makers_reader_and_the_hub_agree_sample_for_sample(board, tmp_path, until):
    rng = np.random.default_rng(45)
    sent = [board_values(k, rng) for k in range(N)]
    data = b"".join(struct.pack("<20f", *v.ravel()) + b"\r\n" for v in sent)
    assert sum(b"\r\n" in data[k * 82 : k * 82 + 80] for k in range(N)) >= N // 3
    ports = [PtyPort(tmp_path / name) for name in ("maker", "reader", "driver")]
    maker_path, reader_path, driver_path = (p.open() for p in ports)
    driver = Registry(only=["anyskin"]).open_device(DeviceConfig("skin", "anyskin", {
        "port": driver_path, "board": board}))
    maker_samples: list[np.ndarray] = []
    opened, ready, written = threading.Event(), threading.Event(), threading.Event()

    def makers_side() -> None:
        sensor, read = makers_reader(board, maker_path)  # opening empties the port, then reads one frame
        opened.set()
        written.wait(0.2)  # the last probe frames arrive
        sensor.reset_input_buffer()
        ready.set()
        written.wait(20)
        maker_samples.extend(read() for _ in range(N - 1))
        sensor.close()

    async def main():
        reader = SerialReader(reader_path, decoder=AnySkinDecoder(joining=True), baudrate=115200)
        got, frames = [], []

        async def consume_reader():
            async for _, sample in reader.frames():
                got.append(sample)

        async def consume_driver():
            async for f in driver.frames():
                frames.append(f)

        tasks = [asyncio.create_task(consume_reader()), asyncio.create_task(consume_driver())]
        await until(lambda: reader.connected and driver.health().reason.startswith(driver_path), "the ports")
        maker = threading.Thread(target=makers_side)
        maker.start()
        probe = struct.pack("<20f", *board_values(0, np.random.default_rng(0)).ravel()) + b"\r\n"
        while not opened.is_set():  # until the maker's reader is open and has read its first frame
            ports[0].write_all(probe)
            await asyncio.sleep(0.05)
        await asyncio.to_thread(ready.wait, 20)
        for p in ports:
            await asyncio.to_thread(p.write_all, data)
        written.set()
        await until(lambda: len(got) == N and len(frames) == N - 4, "every sample")
        await asyncio.to_thread(maker.join, 20)
        await reader.close()
        await driver.close()
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        return got, frames

    got, frames = asyncio.run(main())
    for p in ports:
        p.close()
    assert len(maker_samples) == N - 1
    for k, theirs in enumerate(maker_samples):  # frames 0..43, as the maker's reader gives them
        np.testing.assert_array_equal(theirs, sent[k].ravel().astype(np.float64))
        np.testing.assert_array_equal(np.column_stack([got[k].temperature, got[k].field]).ravel(), theirs)
    assert driver.counters.frames == N and driver.counters.resyncs == 0
    # the driver's frames: each sample turned into the board frame, less the mean of the first five
    r = BOARDS[board].rotations
    as_board = [np.einsum("kij,kj->ki", r, w[:, 1:].astype(np.float64)) for w in sent]
    baseline = np.mean(as_board[:5], axis=0)
    for f, b in zip(frames, as_board[4:], strict=True):
        np.testing.assert_allclose(f.displacement, b - baseline, rtol=0, atol=1e-9)
