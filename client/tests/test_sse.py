"""The SSE parser on the framings servers send: LF, CRLF and CR line ends, messages split anywhere
across chunks, multi-line data, comments, ``retry:``, unnamed and named messages."""

from __future__ import annotations

from wott_client import Message, SSEParser

STREAM = (b": stream open\n\n"
          b"id: 1\ndata: {\"a\":1}\n\n"
          b"id: 2\nevent: skinDeformedDetection\ndata: {\"b\":\n"
          b"data: 2}\n\n"
          b": ping\n\n"
          b"retry: 1500\n\n"
          b"id: 3\ndata:no-space\n\n")
EXPECTED = [Message("1", None, b'{"a":1}'), Message("2", "skinDeformedDetection", b'{"b":\n2}'),
            Message("3", None, b"no-space")]


def _feed(chunks: list[bytes]) -> tuple[list[Message], SSEParser]:
    parser, out = SSEParser(), []
    for c in chunks:
        out += parser.feed(c)
    return out, parser


def test_every_split_of_the_stream_gives_the_same_messages():
    for eol in (b"\n", b"\r\n", b"\r"):
        stream = STREAM.replace(b"\n", eol)
        for cut in range(1, len(stream)):
            got, parser = _feed([stream[:cut], stream[cut:]])
            assert got == EXPECTED, (eol, cut)
            assert parser.retry_ms == 1500


def test_byte_by_byte():
    got, _ = _feed([STREAM[i:i + 1] for i in range(len(STREAM))])
    assert got == EXPECTED


def test_an_incomplete_message_waits_for_its_blank_line():
    parser = SSEParser()
    assert parser.feed(b"id: 9\ndata: x\n") == []
    assert parser.feed(b"\n") == [Message("9", None, b"x")]
