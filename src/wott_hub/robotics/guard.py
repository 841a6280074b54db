"""The Foxglove endpoint's clients kept to a bound the hub chooses (issue 48 items 4 and 6).

Why here: ``foxglove-sdk`` (0.30) owns the sockets and each client's queue, bounded by a count of
messages only (``backlog``): with images on a channel a client that never reads held ~1.76 GB, and
four such grew the hub 8.1 MB/s. Its invalid-message errors are logged one line each (200,000 frames:
17 MB of ERROR lines, and every line takes the GIL from the sensors' loop). The SDK offers no hook for
either, so this module works from outside, as ``nagle.py`` does: the client sockets are this process's
TCP sockets on the endpoint's port (``/proc/self/net/tcp*``), and a client is cut by ``shutdown`` on
a duplicate of its descriptor (the SDK then drops the client and its queue, as for a client that left;
its descriptor is never closed under it).

- ``FoxgloveGuard.tick`` (every ``TICK_S`` on the hub's loop): a client whose socket has had bytes
  waiting in the kernel (``tx_queue``) at every tick for ``STALL_S``, or for as long as the hub logged
  ``CLIENT_MAX_BYTES`` to the endpoint, is cut: its queue can hold no more than what was logged while
  it stalled (plus one tick). More than ``MAX_CLIENTS`` at once: the newest are cut.
- ``InvalidMessages``, a filter on the SDK's client loggers: the first ``LOG_BURST`` invalid-message
  lines a minute are logged, the rest counted (``LogRate``), and so are the send errors a closed
  client's queued replies cause; a client that sends ``INVALID_MAX`` invalid messages is cut and
  named once.
Counters go to ``health()``.
"""

from __future__ import annotations

import logging
import os
import re
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from wott_hub.security.lograte import LogRate

from .nagle import ESTABLISHED, descriptors_of, tcp_sockets

__all__ = ["CLIENT_MAX_BYTES", "INVALID_MAX", "MAX_CLIENTS", "STALL_S", "TICK_S", "FoxgloveGuard",
           "client_sockets"]

log = logging.getLogger("wott_hub.foxglove")

TICK_S = 0.5
STALL_S = 5.0
"""A client whose socket stays backed up this long is not reading (or cannot keep up): it is cut."""
CLIENT_MAX_BYTES = 32 * 2**20
"""What the hub may log to the endpoint while a client's socket is backed up before it is cut: the
bound of what that client's queue can hold (images are ~0.2 MB a message)."""
MAX_CLIENTS = 32
"""Clients at once: the SDK's fan-out runs on the hub's cores; beyond, the newest are cut."""
INVALID_MAX = 20
"""Invalid messages a client may send before it is cut (a real client sends none)."""
LOG_BURST = 10
SDK_CLIENT_LOGGERS = ("foxglove.websocket.connected_client", "foxglove.websocket.connected_client.poller")
_INVALID = re.compile(r"Invalid message from (\S+):(\d+):")
_SEND_ERROR = re.compile(r"Error sending message to client")


def client_sockets(port: int) -> dict[str, tuple[int, int]]:
    """This process's established TCP sockets on local ``port``: inode -> (remote port, bytes waiting
    to be sent or acknowledged)."""
    return {inode: (int(f[2].rpartition(":")[2], 16), int(f[4].partition(":")[0], 16))
            for inode, f in tcp_sockets(port, ESTABLISHED).items()}


def _cut(inodes: set[str]) -> int:
    """``shutdown`` the sockets with these inodes (their descriptors stay the SDK's); how many."""
    done = 0
    for fd in descriptors_of(inodes):
        try:
            dup = socket.socket(fileno=os.dup(fd))
        except OSError:
            continue
        try:
            dup.shutdown(socket.SHUT_RDWR)
            done += 1
        except OSError:
            pass
        finally:
            dup.close()
    return done


class _Client:
    __slots__ = ("backed_since", "logged_at_stall", "seen")

    def __init__(self, seen: float) -> None:
        self.seen = seen
        self.backed_since: float | None = None
        self.logged_at_stall = 0


class InvalidMessages(logging.Filter):
    """On the SDK's client logger: invalid-message lines sampled, and the clients sending them cut."""

    def __init__(self, on_abuse: Callable[[int], None]) -> None:
        super().__init__()
        self.rate = LogRate(log, LOG_BURST, 60.0, "invalid Foxglove messages", logging.WARNING)
        # a client closed with its error statuses still queued: the SDK logs each one it cannot send
        self.send_rate = LogRate(log, LOG_BURST, 60.0, "Foxglove send errors", logging.WARNING)
        self.by_port: dict[int, int] = {}
        self.on_abuse = on_abuse
        self.count = 0
        self._lock = threading.Lock()

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        m = _INVALID.search(text)
        if m is None:
            return _SEND_ERROR.search(text) is None or self.send_rate.allow()
        port = int(m.group(2))
        with self._lock:
            self.count += 1
            if len(self.by_port) > 4096 and port not in self.by_port:  # bounded: old clients' counts go
                self.by_port.clear()
            n = self.by_port[port] = self.by_port.get(port, 0) + 1
        if n == INVALID_MAX:
            self.on_abuse(port)
        return n < INVALID_MAX and self.rate.allow()


class FoxgloveGuard:
    """Watches the endpoint's client sockets (``tick``) and its invalid messages (``InvalidMessages``)."""

    def __init__(self, port: int, logged: Callable[[], int], call_soon: Callable[..., None]) -> None:
        self.port = port
        self.logged = logged  # bytes the hub has logged to the endpoint so far
        self.call_soon = call_soon
        self.clients: dict[str, _Client] = {}
        self.cut_slow = 0
        self.cut_many = 0
        self.cut_invalid = 0
        self.filter = InvalidMessages(self._abusive)
        self._loggers = [logging.getLogger(name) for name in SDK_CLIENT_LOGGERS]

    def install(self) -> None:
        for logger in self._loggers:
            logger.addFilter(self.filter)

    def uninstall(self) -> None:
        for logger in self._loggers:
            logger.removeFilter(self.filter)
        self.filter.rate.flush()
        self.filter.send_rate.flush()

    def _abusive(self, remote_port: int) -> None:
        """Called in the SDK's thread that logged the line: cut at once, there (waiting for the hub's
        loop let ~1,500 more frames through, each a log call taking the GIL from the loop)."""
        inodes = {i for i, (rport, _) in client_sockets(self.port).items() if rport == remote_port}
        if _cut(inodes):
            self.cut_invalid += 1
            self.call_soon(log.warning, "Foxglove: closed the client on port %d: %d invalid messages (a "
                           "client sends none)", remote_port, INVALID_MAX)

    def tick(self) -> None:
        now = time.monotonic()
        found = client_sockets(self.port)
        for gone in set(self.clients) - set(found):
            del self.clients[gone]
        logged = self.logged()
        slow: set[str] = set()
        for inode, (_, waiting) in found.items():
            c = self.clients.get(inode)
            if c is None:
                c = self.clients[inode] = _Client(now)
            if waiting == 0:
                c.backed_since = None
                continue
            if c.backed_since is None:
                c.backed_since, c.logged_at_stall = now, logged
            elif now - c.backed_since >= STALL_S or logged - c.logged_at_stall >= CLIENT_MAX_BYTES:
                slow.add(inode)
        newest = sorted(self.clients, key=lambda i: self.clients[i].seen)[MAX_CLIENTS:]
        many = set(newest) - slow
        if slow:
            self.cut_slow += _cut(slow)
            log.warning("Foxglove: closed %d client(s) that stopped reading (backed up %.0f s or %d MB "
                        "logged meanwhile)", len(slow), STALL_S, CLIENT_MAX_BYTES >> 20)
        if many:
            self.cut_many += _cut(many)
            log.warning("Foxglove: closed %d client(s) beyond the %d served at once", len(many), MAX_CLIENTS)
        for inode in slow | many:
            self.clients.pop(inode, None)

    def health(self) -> dict[str, Any]:
        return {"clients": len(self.clients), "closedSlow": self.cut_slow, "closedOverLimit": self.cut_many,
                "closedInvalid": self.cut_invalid, "invalidMessages": self.filter.count,
                "invalidNotLogged": self.filter.rate.suppressed,
                "sendErrorsNotLogged": self.filter.send_rate.suppressed}
