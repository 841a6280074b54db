"""Bytes to a client's socket now, with tornado's ``IOStream`` taking over only what the socket refuses.

Why: every SSE and WebSocket record the hub writes went through ``IOStream.write`` (and, for
SSE, ``HTTP1Connection.write`` before it): a buffer, two futures and a done-callback per
write, ~7 µs over the ``send`` itself (docs/hub.md, "Where the loop's time goes"). When the
stream has nothing buffered the bytes can go to the socket at once; what the socket does not
take (full, or an error) is handed to ``IOStream.write`` as before, which buffers it, waits for
the socket, and closes the stream on an error as it always has.

Contract: ``send_now`` writes nothing past bytes that tornado still holds (it sends itself only
while ``stream.writing()`` is false), so the order on the wire is the order of the calls; a
closed stream raises ``StreamClosedError`` as ``IOStream.write`` does. Plain TCP only: a TLS
stream (``SSLIOStream``) always goes through tornado, which knows its handshake and its
record layer.
"""

from __future__ import annotations

from asyncio import Future

from tornado.iostream import IOStream, StreamClosedError

__all__ = ["chunk", "send_now"]


def send_now(stream: IOStream, data: bytes) -> Future[None] | None:
    """Send ``data`` on ``stream``: None if the socket took it all, else tornado's future for the rest."""
    if type(stream) is not IOStream or stream.writing():
        return stream.write(data)
    if stream.closed():
        raise StreamClosedError
    try:
        sent = stream.socket.send(data)
    except OSError:  # full (EAGAIN) or broken: tornado's write waits for it, or closes the stream
        sent = 0
    if sent == len(data):
        return None
    return stream.write(memoryview(data)[sent:])


def chunk(data: bytes) -> bytes:
    """``data`` as one HTTP/1.1 chunk (RFC 9112 section 7.1), as ``HTTP1Connection.write`` frames it
    (nothing for no data: an empty chunk would end the response)."""
    return b"%x\r\n%b\r\n" % (len(data), data) if data else b""
