"""One WebSocket to one ``xela_server``, shared by every position read from it in this process.

A server sends every position in every message, so the positions of one server share one connection
(one JSON parse per message, whatever the number of Things); each position's reader subscribes and
gets its own entries, read and checked (``protocol.reading_of``), in a bounded queue (the oldest is
dropped, and counted, when a reader falls behind). The connection lives while someone subscribes. When
the server goes (refused, closed, a network error) every subscriber hears why, and the connection is
made again with the backoff's delays; the Welcome message resets the backoff. Running numbers are
checked: a number that skips counts the messages lost (``gaps``, ``lost``), one that goes back is a
restarted server.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import NamedTuple

from tornado.websocket import WebSocketClientConnection, websocket_connect

from wott_hub.plugin_api import Backoff, Health

from .protocol import Problem, Reading, Update, Welcome, parse, reading_of

__all__ = ["Connection", "Entry", "Subscription", "acquire", "release"]

StateCallback = Callable[[Health, str], None]


class Entry(NamedTuple):
    number: int | None  # the message's running number
    arrival_ns: int  # when it was read (wall clock)
    item: Reading | Problem


class Subscription:
    """One position's entries, as they come."""

    def __init__(self, position: str, on_state: StateCallback, size: int) -> None:
        self.position = position
        self.on_state = on_state
        self.queue: asyncio.Queue[Entry] = asyncio.Queue(size)
        self.dropped = 0

    def put(self, entry: Entry) -> None:
        if self.queue.full():
            self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(entry)


class Connection:
    def __init__(self, url: str, backoff: Backoff, *, connect_timeout_s: float = 5.0, queue_size: int = 256,
                 ) -> None:
        self.url = url
        self.backoff = backoff
        self.connect_timeout_s = connect_timeout_s
        self.queue_size = queue_size
        self.state: tuple[Health, str] = (Health.disconnected, f"connecting to {url}")
        self.messages = self.gaps = self.lost = self.restarts = self.reconnects = 0
        self.subscribers: list[Subscription] = []
        self._expected: int | None = None
        self._ws: WebSocketClientConnection | None = None
        self._task: asyncio.Task[None] | None = None
        self._closing = False

    def subscribe(self, position: str, on_state: StateCallback) -> Subscription:
        sub = Subscription(position, on_state, self.queue_size)
        self.subscribers.append(sub)
        on_state(*self.state)
        if self._task is None:
            self._task = asyncio.create_task(self._run(), name=f"xela {self.url}")
        return sub

    async def unsubscribe(self, sub: Subscription) -> None:
        if sub in self.subscribers:
            self.subscribers.remove(sub)
        if not self.subscribers and self._task is not None:
            task, self._task = self._task, None
            self._closing = True
            if self._ws is not None:
                self._ws.close()  # the closing handshake ends the read, and the socket with it
            try:
                await asyncio.wait_for(asyncio.shield(task), 2.0)
            except TimeoutError:  # between attempts, or a server that never answers the close
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)

    def _set_state(self, state: Health, reason: str) -> None:
        self.state = (state, reason)
        for sub in self.subscribers:
            sub.on_state(state, reason)

    async def _run(self) -> None:
        connected_before = False
        while not self._closing:
            try:
                ws = await websocket_connect(self.url, connect_timeout=self.connect_timeout_s)
            except Exception as e:  # refused, unreachable, a timeout, not a WebSocket server: not now
                self._set_state(Health.disconnected, f"cannot connect to {self.url}: {_text(e)}")
                await asyncio.sleep(self.backoff.next_delay())
                continue
            self._ws = ws
            if connected_before:
                self.reconnects += 1
            connected_before = True
            self._expected = None
            self._set_state(Health.degraded, f"connected to {self.url}, waiting for its messages")
            try:
                reason = await self._read(ws)
            finally:
                self._ws = None
                ws.close()
            if self._closing:
                return
            self._set_state(Health.disconnected, reason)
            await asyncio.sleep(self.backoff.next_delay())

    async def _read(self, ws: WebSocketClientConnection) -> str:
        """Dispatch the server's messages until it goes; why it went."""
        while True:
            try:
                text = await ws.read_message()
            except Exception as e:  # the stream broke under us
                return f"lost {self.url}: {_text(e)}"
            if text is None:
                code = ws.close_code
                return f"{self.url} closed the connection" + (f" (code {code})" if code else "")
            self._dispatch(text, time.time_ns())

    def _dispatch(self, text: str | bytes, arrival_ns: int) -> None:
        msg = parse(text)
        if isinstance(msg, Welcome):
            self.backoff.reset()
            self._set_state(Health.ok, "")
            return
        self.messages += 1
        if isinstance(msg, Problem):
            for sub in self.subscribers:
                sub.put(Entry(None, arrival_ns, msg))
            return
        self._count(msg)
        if self.state[0] != Health.ok:  # data before (or without) a Welcome: the server is there
            self.backoff.reset()
            self._set_state(Health.ok, "")
        for sub in self.subscribers:
            entry = msg.sensors.get(sub.position)
            item = reading_of(sub.position, entry) if entry is not None else Problem(
                f"position {sub.position} is not in the server's messages (it sends "
                f"{', '.join(sorted(msg.sensors, key=int)) or 'none'})")
            sub.put(Entry(msg.number, arrival_ns, item))

    def _count(self, msg: Update) -> None:
        n = msg.number
        if n is None:
            return
        if self._expected is not None and n != self._expected:
            if n > self._expected:
                self.gaps += 1
                self.lost += n - self._expected
            else:
                self.restarts += 1
        self._expected = n + 1


def _text(e: BaseException) -> str:
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__


_shared: dict[tuple[int, str], tuple[Connection, int]] = {}


def acquire(url: str, backoff: Backoff) -> Connection:
    """The connection to ``url`` on this event loop (made on first use), one more user counted."""
    key = (id(asyncio.get_running_loop()), url)
    conn, users = _shared.get(key, (None, 0))
    if conn is None:
        conn = Connection(url, backoff)
    _shared[key] = (conn, users + 1)
    return conn


async def release(conn: Connection, sub: Subscription | None) -> None:
    """One user fewer: its subscription ends; the last one closes the connection."""
    if sub is not None:
        await conn.unsubscribe(sub)
    key = next((k for k, (c, _) in _shared.items() if c is conn), None)
    if key is None:
        return
    _, users = _shared[key]
    if users <= 1:
        del _shared[key]
    else:
        _shared[key] = (conn, users - 1)
