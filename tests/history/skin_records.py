"""Recorded records as the hub writes them: skinDeformedDetection packets in the exact text of
``runtime.payloads.skin_deformed_json`` (intensities rounded to µm), contactInformation changes, and
a Thing registered with a real Tactile TD and its static values (mesh)."""

from __future__ import annotations

import json

import numpy as np

from wott_hub.events.record import KIND_EVENT, KIND_PROPERTY, Record, encode

__all__ = ["busy_scene", "register_device", "skin_json", "skin_records"]


def skin_json(t_ns: int, ids, intensity) -> str:
    nodes = ",".join(f'{{"deformedNodeID":{i},"deformedNodeIntensity":{v!r}}}'
                     for i, v in zip(ids, intensity, strict=True))
    return f'{{"timeStamp":{t_ns},"numOfDeformedNodes":{len(ids)},"arrayOfDeformedNodes":[{nodes}]}}'


def register_device(writer, thing: str, shape: str = "flat") -> tuple[int, int]:
    """Register ``thing`` with the example device's TD and static values; (start seq, node count)."""
    from wott_hub.examples import example_device
    from wott_hub.td.builder import build_tactile_td, static_property_values

    desc = example_device(shape, thing)
    td = build_tactile_td(desc)
    static = static_property_values(desc)
    start = writer.register_thing(thing, title=thing, family="scene", td=json.dumps(td),
                                  static_values=encode(static))
    return start, desc.mesh.n_nodes


def skin_records(thing: str, start: int, frames: int, n_nodes: int, *, t0_ns: int = 1_700_000_000 * 10**9,
                 period_ns: int = 8_333_333, per_frame: int = 20, seed: int = 0) -> list[Record]:
    """``frames`` 120 Hz frames: a skin packet of ~``per_frame`` nodes each, a contacts change every 4th."""
    rng = np.random.default_rng(seed)
    out: list[Record] = []
    seq = start
    for f in range(frames):
        t = t0_ns + f * period_ns
        centre = int(rng.integers(0, max(1, n_nodes - per_frame * 2)))
        ids = np.sort(rng.choice(np.arange(centre, min(n_nodes, centre + per_frame * 2)),
                                 size=min(per_frame, n_nodes), replace=False)).tolist()
        inten = np.round(rng.uniform(0.001, 3.0, len(ids)), 3).tolist()
        seq += 1
        out.append(Record(thing, seq, KIND_EVENT, "skinDeformedDetection", t, skin_json(t, ids, inten)))
        if f % 4 == 0:
            seq += 1
            data = encode({"numOfContacts": 1, "contactLocations": [{"x": f * 0.1, "y": 1.0, "z": 0.0}],
                           "contactForces": [{"x": 0.0, "y": 0.0, "z": -0.25}]})
            out.append(Record(thing, seq, KIND_PROPERTY, "contactInformation", t, data))
    return out


def busy_scene(device_id: str, shape: str = "flat", rate_hz: float = 120.0):
    """A ``scene`` device touching its skin almost all the time (a busy stream to record)."""
    from wott_hub.examples import example_device
    from wott_hub.plugins import DeviceConfig

    mesh = example_device(shape).mesh
    free = mesh.free_indices
    a = [float(v) for v in mesh.nodes[free[len(free) // 2]]]
    b = [float(v) for v in mesh.nodes[free[len(free) // 3]]]
    return DeviceConfig(device_id, "scene", {"shape": shape, "loop": True, "rate_hz": rate_hz, "step": [
        {"kind": "press", "at": a, "start_s": 0.0, "duration_s": 0.6, "depth_mm": 2.0, "radius_mm": 4.0},
        {"kind": "slide", "at": b, "to": a, "start_s": 0.7, "duration_s": 0.6, "depth_mm": 1.5,
         "radius_mm": 4.0}]})
