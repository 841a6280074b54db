"""Server-Sent Events framing, parsed from raw bytes as they arrive.

Written here rather than taken from httpx-sse because the client's throughput is
bounded by this loop: messages are split on blank lines in bytes, and ``data`` is
handed on as bytes (``json.loads`` takes them), so a message costs one split and
no text decoding of the payload. CRLF and CR line ends are normalised first, as
the EventSource specification allows all three.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["Message", "SSEParser"]


class Message(NamedTuple):
    id: str | None  # this message's ``id:`` (None: it had none)
    event: str | None  # its ``event:`` name (None: unnamed, i.e. "message")
    data: bytes


class SSEParser:
    """Feed it chunks; it returns the complete messages in them (comments and empty blocks skipped)."""

    __slots__ = ("_after_cr", "_buf", "retry_ms")

    def __init__(self) -> None:
        self._buf = b""
        self._after_cr = False  # the last chunk ended in CR
        self.retry_ms: int | None = None  # the server's last ``retry:``

    def feed(self, chunk: bytes) -> list[Message]:
        if self._after_cr and chunk[:1] == b"\n":  # the LF of a CRLF split across chunks
            chunk = chunk[1:]
        if b"\r" in chunk:
            self._after_cr = chunk.endswith(b"\r")
            chunk = chunk.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
        else:
            self._after_cr = False
        buf = self._buf + chunk if self._buf else chunk
        blocks = buf.split(b"\n\n")
        self._buf = blocks.pop()
        out: list[Message] = []
        for block in blocks:
            if not block or block[0] == 58:  # b":" a comment (keep-alive, gap notice)
                if b"\n" not in block:
                    continue
            msg = self._message(block)
            if msg is not None:
                out.append(msg)
        return out

    def _message(self, block: bytes) -> Message | None:
        eid = event = None
        data: list[bytes] = []
        for line in block.split(b"\n"):
            if not line or line[0] == 58:
                continue
            name, sep, value = line.partition(b":")
            if sep and value[:1] == b" ":
                value = value[1:]
            if name == b"data":
                data.append(value)
            elif name == b"id":
                if b"\0" not in value:
                    eid = value.decode()
            elif name == b"event":
                event = value.decode() or None
            elif name == b"retry" and value.isdigit():
                self.retry_ms = int(value)
        if not data:
            return None if eid is None else Message(eid, event, b"")
        return Message(eid, event, data[0] if len(data) == 1 else b"\n".join(data))
