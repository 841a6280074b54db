"""The client against a loopback WebSocket server replaying messages of exactly the documented shape
(built here, not by the plugin): every reading of every position read once and exactly, one
connection shared by the positions, a server restart, and bad entries said in health."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest
from wott_driver_xela.simulator import ReplayServer

from wott_hub.plugin_api import Health
from wott_hub.plugins import DeviceConfig, Registry

REGISTRY = Registry(only=["xela"])
SHAPES = {"uSPa46": 24, "uSPa44": 16}


def counts(k: int, n: int, pos: int) -> np.ndarray:
    """Taxel counts of message ``k``: taxel 0's x says k, the rest rest near 30,000."""
    c = 30_000 + (np.arange(3 * n).reshape(n, 3) * 5 + pos * 100 + k % 7)
    c[0, 0] = 30_000 + k % 5000
    return c


def forces(k: int, n: int) -> np.ndarray:
    return np.round(np.sin(np.arange(3 * n) + k) * 0.01, 6).reshape(n, 3)


class Messages:
    """The server's messages: position 1 a uSPa46 (hex data, calibrated), position 2 a uSPa44 (the newer
    list of integers); ``bad`` replaces position 2's entry while set."""

    def __init__(self) -> None:
        self.bad: dict | None = None

    def __call__(self, k: int) -> str:
        t = 1768296808.5 + k / 100
        one = {"time": t, "sensor": "1", "model": "uSPa46", "taxels": 24,
               "data": ",".join(f"{v:04X}" for v in counts(k, 24, 1).ravel()),
               "calibrated": forces(k, 24).ravel().tolist()}
        two = {"time": t, "sensor": "2", "model": "uSPa44", "taxels": 16,
               "data": counts(k, 16, 2).ravel().tolist()}
        return json.dumps({"message": k, "time": t, "sensors": 2, "1": one, "2": self.bad or two,
                           "complete": t + 1e-5})


class Reading:
    """A position's driver read by a task: each frame with the raw counts (and forces) it came from."""

    def __init__(self, url: str, position: int, model: str, **settings) -> None:
        self.driver = REGISTRY.open_device(DeviceConfig(f"xela-{position}", "xela", {
            "url": url, "position": position, "model": model, "backoff_initial_s": 0.05, "backoff_cap_s": 0.2,
            **settings}))
        self.got: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] = []
        self.task = asyncio.create_task(self._consume())

    async def _consume(self) -> None:
        async for f in self.driver.frames():
            raw, force = self.driver.raw_sample("raw"), self.driver.raw_sample("force")
            assert raw is not None
            self.got.append((f.displacement, raw.array, None if force is None else force.array))

    async def close(self) -> None:
        await self.driver.close()
        self.task.cancel()
        await asyncio.gather(self.task, return_exceptions=True)


@pytest.fixture
def server():
    s = ReplayServer(Messages(), rate_hz=100.0)
    s.start()
    yield s
    s.stop()


def test_every_reading_of_each_position_once_and_exactly_over_one_connection(server, until):
    async def main():
        one = Reading(server.url, 1, "uSPa46")
        two = Reading(server.url, 2, "uSPa44")
        await until(lambda: len(one.got) >= 40 and len(two.got) >= 40, "readings of both positions")
        conn = one.driver.connection
        assert conn is two.driver.connection and len(conn.subscribers) == 2
        assert conn.lost == conn.gaps == 0 and one.driver.health().state == Health.ok
        for r, n, pos in ((one, 24, 1), (two, 16, 2)):
            ks = [int(raw[0, 0]) - 30_000 for _, raw, _ in r.got]
            assert ks == list(range(ks[0], ks[0] + len(ks)))  # none lost, none twice
            baseline = np.mean([counts(k, n, pos) for k in range(ks[0] - 9, ks[0] + 1)], axis=0)
            for (change, raw, _), k in zip(r.got, ks, strict=True):
                np.testing.assert_array_equal(raw, counts(k, n, pos))
                np.testing.assert_allclose(change, counts(k, n, pos) - baseline, atol=1e-9)
        await one.close()
        await two.close()
        assert conn.subscribers == []

    asyncio.run(main())


def test_calibrated_forces_as_the_node_vectors(server, until):
    async def main():
        one = Reading(server.url, 1, "uSPa46", forces=True)
        await until(lambda: len(one.got) >= 20, "readings")
        assert one.driver.description.node_signal.quantity == "force"
        for _, raw, force in one.got:
            k = int(raw[0, 0]) - 30_000
            np.testing.assert_array_equal(force, forces(k, 24))
        await one.close()
        two = Reading(server.url, 2, "uSPa44", forces=True)  # position 2 is not calibrated
        await until(lambda: "no calibrated forces" in two.driver.health().reason, "the reason")
        assert two.driver.health().state == Health.degraded and two.got == []
        await two.close()

    asyncio.run(main())


def test_a_server_that_goes_and_comes_back(server, until):
    async def main():
        one = Reading(server.url, 1, "uSPa46")
        await until(lambda: len(one.got) >= 10, "readings")
        server.stop()
        await until(lambda: one.driver.health().state == Health.disconnected, "disconnected")
        await until(lambda: one.driver.health().reason.startswith(f"cannot connect to {server.url}"),
                    "the reconnects failing")
        before = len(one.got)
        server.start()  # the same port again
        await until(lambda: len(one.got) >= before + 20, "readings after the restart")
        assert one.driver.health().state == Health.ok and one.driver.connection.reconnects == 1
        await one.close()

    asyncio.run(main())


@pytest.mark.parametrize(("bad", "reason"), [
    ({"model": "uSPa99", "data": "7530"}, "position 2: model 'uSPa99' is not one this hub knows"),
    ({"model": "uSPa44", "data": [30_000] * 47}, "position 2: 'data' holds 47 values, uSPa44 has 16 taxels"),
    ({"model": "uSPa46", "data": [30_000] * 72}, "the server reports uSPa46 at position 2, this device is"),
])
def test_a_bad_entry_is_a_reason_in_health_and_the_stream_goes_on(bad, reason, until):
    messages = Messages()
    server = ReplayServer(messages, rate_hz=100.0)
    server.start()

    async def main():
        one, two = Reading(server.url, 1, "uSPa46"), Reading(server.url, 2, "uSPa44")
        await until(lambda: len(two.got) >= 5, "readings")
        messages.bad = bad
        await until(lambda: two.driver.health().reason.startswith(reason), "the reason")
        assert two.driver.health().state == Health.degraded
        n_one = len(one.got)
        await until(lambda: len(one.got) > n_one + 10, "position 1 unaffected")
        messages.bad = None
        await until(lambda: two.driver.health().state == Health.ok, "ok again")
        assert two.driver.problems > 0
        await one.close()
        await two.close()

    asyncio.run(main())
    server.stop()


def test_a_position_the_server_does_not_send(server, until):
    async def main():
        five = Reading(server.url, 5, "uSPa44")
        await until(lambda: "position 5 is not in the server's messages (it sends 1, 2)"
                    in five.driver.health().reason, "the reason")
        await five.close()

    asyncio.run(main())
