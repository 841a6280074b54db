"""What several groups and the clients share: the clock, the skinDeformedDetection payload, and
the CPU time of processes (the hub's children count as the hub's: its history process)."""

from __future__ import annotations

import os
import time
from pathlib import Path

__all__ = ["cpu_s", "descendants", "now_ns", "payload", "payload_maker"]

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


def cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid``."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def descendants(pid: int) -> list[int]:
    """The processes ``pid`` started, and theirs (one that exits meanwhile is left out)."""
    out: list[int] = []
    try:
        for task in Path(f"/proc/{pid}/task").iterdir():
            for child in (task / "children").read_text().split():
                out += [int(child), *descendants(int(child))]
    except FileNotFoundError:
        pass
    return out
