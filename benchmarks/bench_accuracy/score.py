"""Contacts and actions of one processed recording, scored against its truth.

Per frame the reported contacts are matched to the fingers by distance (an optimal
assignment; a pair farther apart than the gate is no match). The gate is the larger of
the tip radius and two mesh spacings: a contact that far from every finger is
*spurious* (a side lobe, a noise blip), one that merged two fingers sits between them
and matches one of them at best. Scored:

- right count: the fraction of steady frames (every finger at full depth) with exactly
  as many contacts as fingers;
- location: distance of each matched contact from its finger's centre, steady frames;
- spurious: the fraction of all frames with a contact matched to no finger; phantom:
  rest frames (nothing touching) with any contact;
- force: relative error of each matched contact's |force| against its finger's (truth.py);
- actions: those expected (cases.py) and those reported, in order; slip on a static press;
- speed: ``speedMmPerS`` of the release (and of the first slip) against the scene's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from wott_hub.tactile import FrameResult, SkinMesh

from .families import Recording
from .truth import FrameTruth, release_speed, slip_speed

__all__ = ["CaseScore", "gate_mm", "score", "spacing_mm"]


@dataclass
class CaseScore:
    family: str
    case: str  # kind and placement, "press A"
    steady: int = 0
    right: int = 0
    frames: int = 0
    spurious: int = 0
    rest: int = 0
    phantom: int = 0
    location_mm: list[float] = field(default_factory=list)
    force_rel: list[float] = field(default_factory=list)
    expected: tuple[str, ...] = ()
    reported: list[str] = field(default_factory=list)
    static: bool = False
    release_speed: float | None = None  # reported, mm/s
    release_truth: float = 0.0
    slip_speed: float | None = None
    slip_truth: float = 0.0
    process_us: list[float] = field(default_factory=list)

    @property
    def missed(self) -> list[str]:
        return [a for a in self.expected if a not in self.reported]

    @property
    def false_actions(self) -> list[str]:
        return [a for a in self.reported if a not in self.expected]


def spacing_mm(mesh: SkinMesh) -> float:
    """The median edge length (the bench's own: it also scores processing from before issue 31)."""
    e = mesh.edges
    return float(np.median(np.linalg.norm(mesh.nodes[e[:, 0]] - mesh.nodes[e[:, 1]], axis=1)))


def gate_mm(rec: Recording) -> float:
    return max(rec.case.radius_mm, 2 * spacing_mm(rec.description.mesh))


def _match(contacts: np.ndarray, centres: np.ndarray, gate: float) -> list[tuple[int, int, float]]:
    if not len(contacts) or not len(centres):
        return []
    dist = np.linalg.norm(contacts[:, None, :] - centres[None, :, :], axis=2)
    rows, cols = linear_sum_assignment(dist)
    return [(int(r), int(c), float(dist[r, c])) for r, c in zip(rows, cols, strict=True)
            if dist[r, c] <= gate]


def score(rec: Recording, truths: list[FrameTruth], results: list[FrameResult], times_s: list[float]
          ) -> CaseScore:
    s = CaseScore(rec.family, rec.case.name, expected=rec.case.expected, static=rec.case.static)
    gate = gate_mm(rec)
    for truth, res in zip(truths, results, strict=True):
        locs = np.array([c.location for c in res.contacts]).reshape(-1, 3)
        pairs = _match(locs, truth.centres, gate)
        s.frames += 1
        if len(pairs) < len(res.contacts):
            s.spurious += 1
        if truth.rest:
            s.rest += 1
            s.phantom += bool(res.contacts)
        if truth.steady:
            s.steady += 1
            s.right += len(res.contacts) == len(truth.centres)
            for r, c, d in pairs:
                s.location_mm.append(d)
                if truth.forces[c] > 0:
                    s.force_rel.append(abs(float(np.linalg.norm(res.contacts[r].force)) - truth.forces[c])
                                       / truth.forces[c])
        for e in res.details:
            s.reported.append(e.action)
            if e.action == "release":
                s.release_speed = e.speed_mm_s
            elif e.action == "slip" and s.slip_speed is None:
                s.slip_speed = e.speed_mm_s
    s.release_truth = release_speed(rec.scene, rec.description.mesh)
    s.slip_truth = slip_speed(rec.scene, rec.description.mesh)
    s.process_us = [t * 1e6 for t in times_s]
    return s
