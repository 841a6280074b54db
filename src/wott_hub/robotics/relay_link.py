"""The hub's end of the Foxglove relay (``relay.py``): the process started, its frames read, the hub's
frames written without ever blocking the loop.

``RelayLink`` starts ``python -m wott_hub.robotics.relay`` with one end of each of two socket pairs
(the hub writes "down" on its loop through ``Outbox``, reads "up" in a thread), waits for its
``READY``, hands each ``SUB`` to the hub's loop, keeps its ``HEALTH``, writes its ``LOGREC`` lines
with the hub's logging, and stops it (``STOP``, then a kill after ``STOP_S``). Split from ``live.py``,
which maps the hub's records to channels and messages.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import socket
import subprocess
import sys
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

from . import relay_wire as W
from .guard import CLIENT_MAX_BYTES

__all__ = ["RELAY_BYTES", "Outbox", "RelayLink"]

log = logging.getLogger("wott_hub.foxglove")

RELAY_BYTES = CLIENT_MAX_BYTES
"""What waits for the relay's socket at most (the relay fell behind: a loaded machine); beyond, a
message is not sent to the viewers, and counted (``notSent``): the sensors never wait for it."""
START_S = 30.0  # the relay's server bound, at most (a Python start and the SDK's import: ~0.5 s)
STOP_S = 5.0  # the relay's end after STOP, at most; then it is killed


class Outbox:
    """Frames for the relay, written on the hub's loop to a non-blocking socket: a message costs the loop
    one ``sendmsg`` (the kernel copies it once), whatever the number of viewers. What the socket does not
    take waits here and goes when it is writable (``add_writer``), bounded in bytes: a ``LOG`` frame
    that would take it past ``RELAY_BYTES`` is refused and counted; control frames always go. (A thread
    writing a blocking socket cost more: every message woke it, and each wake-up took the GIL from the
    devices' pipelines on a busy machine.)"""

    def __init__(self, sock: socket.socket, loop: asyncio.AbstractEventLoop) -> None:
        sock.setblocking(False)
        self.sock = sock
        self.loop = loop
        self.pending: deque[bytes | memoryview] = deque()
        self.bytes = 0  # pending
        self.refused = 0
        self.failed = ""

    def put(self, frame: tuple[bytes, bytes], *, droppable: bool = True) -> bool:
        head, body = frame
        if self.failed:
            return False
        total = len(head) + len(body)
        if self.pending:  # behind what waits: in order, or not at all
            if droppable and self.bytes + total > RELAY_BYTES:
                self.refused += 1
                return False
            self.pending += (head, body)
            self.bytes += total
            return True
        try:
            sent = self.sock.sendmsg([head, body])
        except BlockingIOError:
            sent = 0
        except OSError as e:  # the relay is gone: the reader says so
            self.failed = str(e)
            return False
        if sent == total:
            return True
        if sent < len(head):  # a frame begun is finished whatever the bound
            self.pending += (memoryview(head)[sent:], body)
        else:
            self.pending.append(memoryview(body)[sent - len(head):])
        self.bytes += total - sent
        self.loop.add_writer(self.sock.fileno(), self._flush)
        return True

    def _flush(self) -> None:
        pending = self.pending
        while pending:
            try:
                sent = self.sock.sendmsg([pending[i] for i in range(min(len(pending), 64))])
            except BlockingIOError:
                return
            except OSError as e:
                self.failed = str(e)
                pending.clear()
                self.bytes = 0
                break
            self.bytes -= sent
            while sent:
                n = len(pending[0])
                if sent >= n:
                    pending.popleft()
                    sent -= n
                else:
                    pending[0] = memoryview(pending[0])[sent:]
                    sent = 0
        self.loop.remove_writer(self.sock.fileno())

    def close(self, timeout: float) -> None:
        """What waits, written within ``timeout`` (the hub stops: the loop no longer writes it)."""
        if self.pending:
            self.loop.remove_writer(self.sock.fileno())
        if self.failed:
            return
        self.sock.settimeout(timeout)
        try:
            for part in self.pending:
                self.sock.sendall(part)
        except OSError as e:
            self.failed = str(e)
        self.pending.clear()
        self.bytes = 0


class RelayLink:
    """The relay process and its two sockets (module doc). ``on_sub(topic, change)`` and ``on_ended()``
    are called on ``loop``."""

    def __init__(self, loop: asyncio.AbstractEventLoop, on_sub: Callable[[str, int], None],
                 on_ended: Callable[[], None]) -> None:
        self.loop = loop
        self.on_sub, self.on_ended = on_sub, on_ended
        self.process: subprocess.Popen[bytes] | None = None
        self.outbox: Outbox | None = None
        self.port: int | None = None
        self.health: dict[str, Any] = {}  # the relay's last HEALTH
        self._socks: list[socket.socket] = []
        self._stopping = False

    def start(self, init: dict[str, Any], what: str, hint: str) -> None:
        """The process started and its server bound (``init``: ``relay.py``'s INIT); an ``OSError`` naming
        ``what`` (and ``hint``) if it could not bind."""
        down, down_theirs = socket.socketpair()
        up, up_theirs = socket.socketpair()
        fds = (down_theirs.fileno(), up_theirs.fileno())
        self.process = subprocess.Popen([sys.executable, "-m", "wott_hub.robotics.relay", *map(str, fds)],
                                        pass_fds=fds, stdin=subprocess.DEVNULL)
        down_theirs.close()
        up_theirs.close()
        self._socks = [down, up]
        W.send(down, W.control(W.INIT, init))
        up.settimeout(START_S)
        try:
            ready = self._ready(up)
        except (OSError, TimeoutError) as e:
            ready = {"error": f"the relay process did not start: {e}"}
        up.settimeout(None)
        if "error" in ready:
            self._end()
            text = ready["error"]
            code = errno.EADDRINUSE if "in use" in text else errno.EADDRNOTAVAIL
            raise OSError(code, f"{what}: {text} {hint}")
        self.port = int(ready["port"])
        if not ready["nagle"]:
            log.warning("Foxglove: the listener on port %s was not found to turn Nagle's algorithm off "
                        "(not Linux?): messages may wait up to 40 ms for the client's ACK", self.port)
        self.outbox = Outbox(down, self.loop)
        threading.Thread(target=self._read, args=(up,), name="foxglove-relay", daemon=True).start()

    def put(self, frame: tuple[bytes, bytes], *, droppable: bool = True) -> bool:
        """``frame`` to the relay (``Outbox.put``); False if it was not taken."""
        outbox = self.outbox
        return outbox is not None and outbox.put(frame, droppable=droppable)

    @staticmethod
    def _ready(sock: socket.socket) -> dict[str, Any]:
        """The relay's ``READY`` (its log lines before it are written as they come)."""
        while True:
            frame = W.recv(sock)
            if frame is None:
                return {"error": "the relay process ended before its server started"}
            kind, body = frame
            if kind == W.READY:
                return dict(body)
            if kind == W.LOGREC:
                level, name, text = body
                logging.getLogger(name).log(level, "%s", text)

    def _read(self, sock: socket.socket) -> None:
        """The relay's frames (a thread): subscriptions to the hub's loop, health kept, log lines written."""
        while True:
            try:
                frame = W.recv(sock)
            except OSError:
                frame = None
            if frame is None:
                self._soon(self._ended)
                return
            kind, body = frame
            if kind == W.SUB:
                self._soon(self.on_sub, *body)
            elif kind == W.HEALTH:
                self.health = body
            elif kind == W.LOGREC:
                level, name, text = body
                logging.getLogger(name).log(level, "%s", text)

    def _soon(self, fn: Any, *args: Any) -> None:
        if not self.loop.is_closed():
            self.loop.call_soon_threadsafe(fn, *args)

    def _ended(self) -> None:
        if self._stopping:
            return
        code = self.process.poll() if self.process is not None else None
        log.error("Foxglove: the relay process ended (exit code %s): the endpoint is down until the hub "
                  "restarts", code)
        self.health = {**self.health, "relay": "ended"}
        self.on_ended()

    def stop(self) -> None:
        self._stopping = True
        if self.outbox is not None:
            self.outbox.put(W.control(W.STOP, None), droppable=False)
            self.outbox.close(STOP_S)
            self.outbox = None
        self._end()
        self.port = None

    def _end(self) -> None:
        process, self.process = self.process, None
        if process is not None:
            try:
                process.wait(STOP_S)
            except subprocess.TimeoutExpired:
                log.warning("Foxglove: the relay process did not end in %.0f s; killed", STOP_S)
                process.kill()
                process.wait(STOP_S)
        for sock in self._socks:
            sock.close()
        self._socks = []
