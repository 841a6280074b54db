"""The frames between the hub and its Foxglove relay process (``relay.py``), over one socket pair.

A frame is ``<u32 length><u8 kind>`` then its body (length counts the kind and the body). A message
to log (``LOG``) is ``<u32 channel id><u64 log time ns>`` then the payload's bytes as encoded once by
the mapping; everything else (channels, subscriptions, health, log lines) is rare and pickled (both
ends are this program). ``send`` hands the header and the payload to the kernel in one ``sendmsg``:
the payload is never copied into a frame on the hub's side.
"""

from __future__ import annotations

import pickle
import socket
import struct
from typing import Any

__all__ = ["CHANNEL", "CLOSE", "HEALTH", "INIT", "LOG", "LOGREC", "READY", "STOP", "SUB", "control",
           "log_frame", "recv", "send"]

# hub -> relay
INIT, CHANNEL, CLOSE, LOG, STOP = 1, 2, 3, 4, 5
# relay -> hub
READY, SUB, HEALTH, LOGREC = 11, 12, 13, 14

_HEAD = struct.Struct("<IB")
_LOG = struct.Struct("<IQ")


def log_frame(channel: int, t_ns: int, payload: bytes) -> tuple[bytes, bytes]:
    """A ``LOG`` frame as its header and the payload itself (``send`` writes both without joining them)."""
    return _HEAD.pack(1 + _LOG.size + len(payload), LOG) + _LOG.pack(channel, t_ns), payload


def control(kind: int, value: Any) -> tuple[bytes, bytes]:
    body = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEAD.pack(1 + len(body), kind), body


def send(sock: socket.socket, frame: tuple[bytes, bytes]) -> None:
    """Blocking (the kernel's buffer full: the caller's thread waits, never the hub's loop)."""
    head, body = frame
    sent = sock.sendmsg([head, body])
    total = len(head) + len(body)
    if sent < total:
        rest = (head + body)[sent:] if sent < len(head) else memoryview(body)[sent - len(head):]
        sock.sendall(rest)


def _exactly(sock: socket.socket, n: int) -> bytes | None:
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        k = sock.recv_into(view[got:])
        if k == 0:
            return None
        got += k
    return bytes(buf)


def recv(sock: socket.socket) -> tuple[int, Any] | None:
    """The next frame: (kind, body): for ``LOG`` (channel id, log time, payload bytes), else the unpickled
    value; None at the end of the stream (the other side is gone)."""
    head = _exactly(sock, _HEAD.size)
    if head is None:
        return None
    length, kind = _HEAD.unpack(head)
    body = _exactly(sock, length - 1) if length > 1 else b""
    if body is None:
        return None
    if kind == LOG:
        channel, t_ns = _LOG.unpack_from(body)
        return kind, (channel, t_ns, body[_LOG.size:])
    return kind, pickle.loads(body)
