"""Contact tracking: each finger keeps its contact id from frame to frame.

Segmentation sees one frame; a user sees fingers. So each frame's contacts are
matched to the previous frame's tracks by distance: a track's predicted place is
its last location moved by its last velocity over the frame's interval, and a
contact farther than the gate from every prediction is no match. (A contact of the
very nodes a track's last contact had, a press held while the deformed set stays
the same, is that track's without a distance.) The gate follows the skin
(``gate_mm``: a few mesh spacings, so one frame's travel of a fast slide stays
inside it, and a neighbouring finger two tip radii away stays out); the
assignment is greedy by distance, which is optimal for the few contacts a skin
carries at once unless two fingers cross within one frame.

What a track needs and a new contact does not is evidence: a contact that
continues a track is kept while it is deformed at all (above ε), but a new one
is born only if its peak rises ``birth_mm`` above its base (ε, or the valley to
a higher neighbour): a noise blip on a camera skin's first free ring, or a
valley wobble, does not flicker in and out as a finger. And a contact whose
peak is below ``side_lobe_ratio`` of the frame's strongest is an artefact of the
device's estimate (a camera model's side lobe), not a finger: dropped.
Ids count up from 1 for the processor's life; a contact not matched in a frame
ends its track, and its finger, if it comes back, gets a new id.
"""

from __future__ import annotations

from dataclasses import dataclass

from .contacts import Contact

__all__ = ["ContactTracker"]

MIN_DT_S = 1e-3


@dataclass(slots=True)
class _Track:
    id: int
    x: float
    y: float
    z: float
    t_ns: int
    nodes: object  # the node array of its last contact: the same object while the split is kept
    vx: float = 0.0
    vy: float = 0.0
    vz: float = 0.0


class ContactTracker:
    """Feed it each frame's contacts (largest first); it returns those it keeps, with their ids."""

    def __init__(self, gate_mm: float) -> None:
        if not gate_mm > 0:
            raise ValueError(f"gate must be positive, got {gate_mm}")
        self.gate_mm = gate_mm
        self._tracks: list[_Track] = []
        self._next = 1

    def reset(self) -> None:
        """Forget every track (the skin is at rest)."""
        self._tracks = []

    def update(self, t_ns: int, contacts: list[Contact], birth_mm: float, side_lobe_ratio: float
               ) -> list[Contact]:
        if not contacts:
            self._tracks = []
            return contacts
        tracks = self._tracks
        if len(contacts) == 1 and len(tracks) == 1:  # one finger still there (the common case)
            c, tr = contacts[0], tracks[0]
            if c.nodes is tr.nodes or self._near(t_ns, c.xyz, tr):
                self._move(tr, c, t_ns)
                return contacts
        if side_lobe_ratio > 0 and len(contacts) > 1:
            strongest = max(c.peak for c in contacts)
            contacts = [c for c in contacts if c.peak >= side_lobe_ratio * strongest]
        owner = self._assign(t_ns, contacts, tracks) if tracks else [None] * len(contacts)
        out: list[Contact] = []
        kept: list[_Track] = []
        for c, found in zip(contacts, owner, strict=True):
            if found is None:
                if c.peak - c.base < birth_mm:
                    continue
                x, y, z = c.xyz
                tr = _Track(self._next, x, y, z, t_ns, c.nodes)
                self._next += 1
                c.id = tr.id  # a contact of this frame, not yet handed to anyone
            else:
                tr = found
                self._move(tr, c, t_ns)
            kept.append(tr)
            out.append(c)
        self._tracks = kept
        return out

    @staticmethod
    def _move(tr: _Track, c: Contact, t_ns: int) -> None:
        """``tr`` continues as ``c`` (which takes its id)."""
        x, y, z = c.xyz
        dt = (t_ns - tr.t_ns) / 1e9
        if dt >= MIN_DT_S:  # two frames stamped (nearly) together say nothing of a velocity
            tr.vx, tr.vy, tr.vz = (x - tr.x) / dt, (y - tr.y) / dt, (z - tr.z) / dt
        tr.x, tr.y, tr.z, tr.t_ns, tr.nodes = x, y, z, t_ns, c.nodes
        c.id = tr.id

    def _near(self, t_ns: int, loc: tuple[float, float, float], tr: _Track) -> bool:
        dt = (t_ns - tr.t_ns) / 1e9
        x, y, z = loc
        d2 = (x - tr.x - tr.vx * dt) ** 2 + (y - tr.y - tr.vy * dt) ** 2 + (z - tr.z - tr.vz * dt) ** 2
        return d2 <= self.gate_mm * self.gate_mm

    def _assign(self, t_ns: int, contacts: list[Contact], tracks: list[_Track]) -> list[_Track | None]:
        """Each contact's track (None: a new finger): a contact of the very nodes a track's last one
        had (the deformed set and its split unchanged: a held press) is that track's; the others
        by distance, nearest pairs first, within the gate."""
        by_nodes = {id(tr.nodes): tr for tr in tracks}
        owner: list[_Track | None] = [by_nodes.pop(id(c.nodes), None) for c in contacts]
        if not by_nodes or None not in owner:
            return owner
        left = list(by_nodes.values())
        open_ = [i for i, tr in enumerate(owner) if tr is None]
        for i, tr in zip(open_, self._nearest(t_ns, [contacts[i] for i in open_], left), strict=True):
            owner[i] = tr
        return owner

    def _nearest(self, t_ns: int, contacts: list[Contact], tracks: list[_Track]) -> list[_Track | None]:
        """Each contact's track by distance to the tracks' predictions, nearest pairs first, in the gate."""
        gate2 = self.gate_mm * self.gate_mm
        pairs = []
        locs = [c.xyz for c in contacts]
        for j, tr in enumerate(tracks):
            dt = (t_ns - tr.t_ns) / 1e9
            px, py, pz = tr.x + tr.vx * dt, tr.y + tr.vy * dt, tr.z + tr.vz * dt
            for i, (x, y, z) in enumerate(locs):
                d2 = (x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2
                if d2 <= gate2:
                    pairs.append((d2, i, j))
        owner: list[_Track | None] = [None] * len(locs)
        if len(pairs) == 1:
            owner[pairs[0][1]] = tracks[pairs[0][2]]
            return owner
        pairs.sort()
        taken = set()
        for _, i, j in pairs:
            if owner[i] is None and j not in taken:
                owner[i] = tracks[j]
                taken.add(j)
        return owner
