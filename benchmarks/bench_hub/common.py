"""What several groups and the clients share: the clock and the skinDeformedDetection payload."""

from __future__ import annotations

import time

__all__ = ["now_ns", "payload", "payload_maker"]

now_ns = time.perf_counter_ns


def payload(n_nodes: int, stamp: int) -> dict:
    return {"timeStamp": stamp, "numOfDeformedNodes": n_nodes,
            "arrayOfDeformedNodes": [
                {"deformedNodeID": 17 * i, "deformedNodeIntensity": round(0.1 + i / 97, 3)}
                for i in range(n_nodes)]}


def payload_maker(n_nodes: int = 20):
    """k -> the encoded payload with timeStamp k: encoded once, the counter spliced in (the hub's own
    JSON encoding of frames is measured by the latency group's "encoding" stage)."""
    from wott_hub.events.record import encode

    body = encode(payload(n_nodes, 0))
    head, tail = body.split("0", 1)[0], body.split(",", 1)[1]
    assert head == '{"timeStamp":'
    return lambda k: f"{head}{k},{tail}"
