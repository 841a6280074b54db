"""A stand-in for ``xela_server`` on 127.0.0.1: the documented messages over a real WebSocket.

``ReplayServer`` serves whatever messages it is given: each client gets the Welcome when it connects,
then every client message ``k`` at ``rate_hz`` (the server's running number counts on whether anyone
listens or not; with ``hold``, from ``release`` on). It runs in a thread of its own, as a separate
program would, and can be stopped and started again on the same port (a server restart).
``XelaSimulator`` makes the messages: the shape of ``protocol``'s sources (``message``, ``time``, one
key per position with ``sensor``, ``model``, ``time``, ``taxels``, ``data`` as comma-separated 4-digit
hex, ``calibrated`` when asked), counts resting near 30,000 with a little noise, and a press
(``press``) that raises a taxel's z and its neighbours'. A toy for tests, the benchmark and trying the
hub without a sensor.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import tornado.httpserver
import tornado.netutil
import tornado.web
import tornado.websocket

from .protocol import MODELS

__all__ = ["WELCOME", "ReplayServer", "XelaSimulator"]

WELCOME = json.dumps({"message": "Welcome", "time": 0.0, "version": "wott-hub simulator"})
REST_COUNTS = 30000.0
COUNTS_PER_NEWTON = 2000.0  # the toy's calibration


class _Client(tornado.websocket.WebSocketHandler):
    def initialize(self, server: ReplayServer) -> None:
        self.server = server

    def open(self, *args: str, **kwargs: str) -> None:
        self.server.clients.add(self)
        self.write_message(self.server.welcome)

    def on_close(self) -> None:
        self.server.clients.discard(self)

    def on_message(self, message: str | bytes) -> None:
        """A client has nothing to say to this server."""


class ReplayServer:
    def __init__(self, message: Callable[[int], str], *, rate_hz: float = 100.0, welcome: str = WELCOME,
                 port: int = 0, hold: bool = False) -> None:
        self.message = message
        self.rate_hz = rate_hz
        self.welcome = welcome
        self.port = port
        self.clients: set[_Client] = set()
        self.sent = 0  # messages made (the next running number)
        self.delivered = 0  # messages written to a client
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._released = threading.Event()
        if not hold:
            self._released.set()
        self._stopping: asyncio.Event | None = None

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def start(self) -> str:
        """Listen (on ``port``, a free one the first time) and send; returns the URL."""
        self._ready.clear()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._serve()), name="xela-sim",
                                        daemon=True)
        self._thread.start()
        if not self._ready.wait(10):
            raise RuntimeError("the simulated xela_server did not start")
        return self.url

    def release(self) -> None:
        """Start sending (a server made with ``hold``)."""
        self._released.set()

    def stop(self) -> None:
        """Close every connection and stop listening (the server went away)."""
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None:
            loop.call_soon_threadsafe(stopping.set)
        if self._thread is not None:
            self._thread.join(10)
        self._thread = None

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stopping = asyncio.Event()
        app = tornado.web.Application([(r"/", _Client, {"server": self})])
        sockets = tornado.netutil.bind_sockets(self.port, "127.0.0.1")
        self.port = sockets[0].getsockname()[1]  # the same port again on a restart
        http = tornado.httpserver.HTTPServer(app)
        http.add_sockets(sockets)
        self._ready.set()
        period = 1.0 / self.rate_hz
        try:
            while not (self._released.is_set() or self._stopping.is_set()):
                await asyncio.sleep(0.01)
            due = self._loop.time()
            while not self._stopping.is_set():
                text = self.message(self.sent)
                self.sent += 1
                for client in list(self.clients):
                    try:
                        client.write_message(text)
                        self.delivered += 1
                    except tornado.websocket.WebSocketClosedError:
                        self.clients.discard(client)
                due += period
                delay = due - self._loop.time()
                if delay < -period:  # late: skip time, not messages
                    due = self._loop.time()
                try:
                    await asyncio.wait_for(self._stopping.wait(), max(0.0, delay))
                except TimeoutError:
                    pass
        finally:
            http.stop()
            for client in list(self.clients):
                client.close()
            await http.close_all_connections()


class XelaSimulator:
    """Messages of a server with sensors at ``positions`` (position -> model)."""

    def __init__(self, positions: dict[int, str], *, calibrated: bool = False, noise: float = 3.0,
                 seed: int = 0) -> None:
        self.positions = {str(p): m for p, m in positions.items()}
        self.calibrated = calibrated
        self.noise = noise
        self._rng = np.random.default_rng(seed)
        self._press: dict[str, np.ndarray] = {}  # position -> (taxels,) normal force, N

    def press(self, position: int, taxel: int | None, newtons: float = 1.0) -> None:
        """Press taxel ``taxel`` (row-major from the top left) of ``position`` (None: release): it and its
        four neighbours (half as much) feel a normal force."""
        key = str(position)
        rows, cols = MODELS[self.positions[key]]
        force = np.zeros(rows * cols)
        if taxel is not None:
            r, c = divmod(taxel, cols)
            force[taxel] = newtons
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                if 0 <= r + dr < rows and 0 <= c + dc < cols:
                    force[(r + dr) * cols + c + dc] = newtons / 2
        self._press[key] = force

    def entry(self, position: str, now: float) -> dict[str, Any]:
        rows, cols = MODELS[self.positions[position]]
        n = rows * cols
        forces = np.zeros((n, 3))
        forces[:, 2] = self._press.get(position, np.zeros(n))
        counts = REST_COUNTS + COUNTS_PER_NEWTON * forces + self._rng.normal(0.0, self.noise, (n, 3))
        data = ",".join(f"{int(v):04X}" for v in np.clip(np.rint(counts), 0, 0xFFFF).ravel())
        out: dict[str, Any] = {"time": now, "sensor": position, "data": data,
                               "model": self.positions[position], "taxels": n}
        if self.calibrated:
            out["calibrated"] = [round(float(v), 6) for v in forces.ravel()]
        return out

    def message(self, k: int) -> str:
        now = time.time()
        msg: dict[str, Any] = {"message": k, "time": now, "sensors": len(self.positions)}
        for position in self.positions:
            msg[position] = self.entry(position, now)
        return json.dumps(msg)
