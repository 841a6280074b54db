"""Decoding alone, no network: ``skinDisplacement`` packets of 20 nodes into NumPy arrays, one process.

The binary form through ``wott_client.PacketParser`` (the stream's bytes in 64 KiB chunks, as a
socket hands them), and the same packets' JSON through the client's SSE parser and
``displacement_of_text``: what the binary form saves a consumer.
"""

from __future__ import annotations

import time

import numpy as np

__all__ = ["NODES", "decode_rates", "packets"]

NODES = 20


def packets(n: int, nodes: int = NODES, seed: int = 3) -> list:
    """``n`` FieldRecords of ``nodes`` nodes each (a fingertip on a 16 x 16 pad), seq 1..n."""
    from wott_hub.events.fields import FieldArrays, FieldRecord

    rng = np.random.default_rng(seed)
    t0 = 1_763_000_000 * 10**9
    out = []
    for k in range(n):
        ids = np.sort(rng.choice(256, nodes, replace=False))
        field = FieldArrays.of(ids, rng.normal(0, 1.0, (nodes, 3)))
        rec = FieldRecord("bench", k + 1, t0 + k * 8_333_333, field)
        out.append(rec)
    return out


def _chunks(data: bytes, size: int = 1 << 16) -> list[bytes]:
    return [data[i:i + size] for i in range(0, len(data), size)]


def decode_rates(n: int) -> dict[str, tuple[int, float, int]]:
    """form -> (packets decoded, seconds, bytes per packet)."""
    from wott_client import PacketParser, SSEParser
    from wott_client._fields import displacement_of_text

    recs = packets(n)
    binary = b"".join(r.binary() for r in recs)
    sse = b"".join(r.sse() for r in recs)
    out: dict[str, tuple[int, float, int]] = {}
    parser = PacketParser("bench")
    chunks = _chunks(binary)
    got = 0
    t0 = time.perf_counter()
    for chunk in chunks:
        for p in parser.feed(chunk):
            got += len(p.vectors) > 0
    out["binary (application/vnd.wott.skin-displacement)"] = (got, time.perf_counter() - t0, len(binary) // n)
    sse_parser = SSEParser()
    chunks = _chunks(sse)
    got = 0
    t0 = time.perf_counter()
    for chunk in chunks:
        for m in sse_parser.feed(chunk):
            got += len(displacement_of_text("bench", m.id, m.data).vectors) > 0
    out["JSON over SSE"] = (got, time.perf_counter() - t0, len(sse) // n)
    return out
