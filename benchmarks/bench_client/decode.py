"""Decoding alone, no network: what one process can turn into NumPy fields per second.

wott-client: a stream's bytes (the hub's framing: ``id:``, ``event:``, ``data:``) through its SSE
parser and decoder, in 16 KiB chunks as a socket would hand them. wotpy: its WebSocket client's
per-message parse (``WebsocketMessageEmittedItem.from_raw``, which validates with jsonschema),
then the same dense field.
"""

from __future__ import annotations

import json
import time

from .hubside import EVENT, packet_maker

__all__ = ["decode_rates"]


def _ours(n: int) -> tuple[int, float]:
    from wott_client import SSEParser
    from wott_client._frames import Decoder
    from wott_client._td import parse_mesh

    from wott_hub.examples import example_device
    from wott_hub.td.builder import static_property_values

    values = static_property_values(example_device("flat"))
    mesh = parse_mesh(values["skinNodes"], values["skinCells"])
    make = packet_maker(len(mesh))
    stream = b"".join(f"id: {k}\nevent: {EVENT}\ndata: {make(k)}\n\n".encode() for k in range(n))
    chunks = [stream[i:i + 16384] for i in range(0, len(stream), 16384)]
    parser, decoder = SSEParser(), Decoder("bench", mesh)
    got = 0
    t0 = time.perf_counter()
    for chunk in chunks:
        for m in parser.feed(chunk):
            decoder.decode(m.event or EVENT, m.id, m.data)
            got += 1
    return got, time.perf_counter() - t0


def _wotpy(n: int) -> tuple[int, float]:
    import numpy as np
    from wotpy.protocols.ws.messages import WebsocketMessageEmittedItem

    make = packet_maker(256)
    raw = [json.dumps({"subscription": "x" * 36, "name": EVENT, "data": json.loads(make(k))})
           for k in range(n)]
    t0 = time.perf_counter()
    for r in raw:
        nodes = WebsocketMessageEmittedItem.from_raw(r).data["arrayOfDeformedNodes"]
        field = np.zeros(256)
        field[[d["deformedNodeID"] for d in nodes]] = [d["deformedNodeIntensity"] for d in nodes]
    return n, time.perf_counter() - t0


def decode_rates(n: int) -> dict[str, tuple[int, float]]:
    """client -> (records, seconds)."""
    return {"wott-client": _ours(n), "wotpy ConsumedThing": _wotpy(max(200, n // 50))}
