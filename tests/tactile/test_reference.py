"""The fast FrameProcessor against a straightforward reference: identical results, bit for bit.

The processor keeps the last split into patches, gathers only what it needs,
sums every statistic in one ``reduceat`` and tracks actions in Python floats
(issue 18). The reference below does none of that: each frame from scratch,
patches from SciPy's connected components, one array operation per statistic
as the processor did before, the action detector on NumPy vectors. Frames
carry several contacts, patches that touch (one contact), presses held over
several frames (the kept split is reused), slides, pinches and releases.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from wott_hub.tactile import (
    ActionParams,
    FrameProcessor,
    ProcessingParams,
    SkinMesh,
    TactileFrame,
    flat_pad,
    load_taclink_barrel,
)
from wott_hub.tactile.indentation import Indenter, indent

PAD = flat_pad(24, 24, pitch_mm=1.5)


@pytest.fixture(scope="module")
def barrel(shared_data):
    d = shared_data / "taclink"
    return load_taclink_barrel(d / "barrel_skin.vtk", d / "node_idx.csv", d / "label_idx.csv")


def reference_contacts(mesh: SkinMesh, deformed, intensity, d, stiffness, min_nodes):
    """(nodes, location, force, intensity, peak, shear, depth) per contact, largest first."""
    _, labels = connected_components(mesh.adjacency[deformed][:, deformed], directed=False)
    firsts = {int(lab): int(deformed[labels == lab][0]) for lab in labels}  # patches by their smallest node
    patches = [deformed[labels == lab] for lab in sorted(firsts, key=firsts.__getitem__)]
    nodes = np.concatenate(patches)
    counts = np.array([len(p) for p in patches])
    starts = np.concatenate(([0], np.cumsum(counts[:-1])))
    w = intensity[nodes]
    total = np.add.reduceat(w, starts)
    location = np.add.reduceat(w[:, None] * mesh.nodes[nodes], starts) / total[:, None]
    peak = np.maximum.reduceat(w, starts)
    dn, n = d[nodes], mesh.normals[nodes]
    normal = np.einsum("ij,ij->i", dn, n)
    shear = np.add.reduceat(dn - normal[:, None] * n, starts) / counts[:, None]
    depth = np.add.reduceat(np.abs(normal), starts) / counts
    return [(patches[c], location[c], stiffness[patches[c]] @ d[patches[c]], float(total[c]), float(peak[c]),
             shear[c], float(depth[c]))
            for c in np.argsort(-total, kind="stable") if counts[c] >= min_nodes]


def norm3(v) -> float:
    # in order, no fused multiply-add, as the implementation sums: ``v @ v`` goes to the BLAS, whose
    # kernel (FMA or not) depends on the CPU, and the last bit with it
    x, y, z = v.tolist()
    return math.sqrt(x * x + y * y + z * z)


class ReferenceActions:
    """The action state machine of wott_hub.tactile.actions, on NumPy vectors."""

    def __init__(self, p: ActionParams) -> None:
        self.p = p
        self.onset = self.last_rest = self.prev_ns = self.still_since = None
        self.anchor = self.prev_loc = None
        self.slipping = self.pressed = self.pinched = False
        self.pinch_d0 = self.pinch_start = self.pinch_prev = None
        self.speed = self.moved = self.approach = 0.0

    def update(self, t_ns, contacts):
        """The actions and, per action, (confidence, contacts, duration, speed, moved, approach)."""
        p, out, onset = self.p, [], self.onset
        if not contacts:
            if self.onset is not None:
                if (t_ns - self.onset) / 1e9 < p.pat_s and not self.pressed:
                    out.append("pat")
                out.append("release")
                self.onset = self.anchor = self.prev_loc = self.still_since = None
                self.slipping = self.pressed = self.pinched = False
                self.pinch_d0 = self.pinch_start = self.pinch_prev = None
                self.moved = self.approach = 0.0
            self.last_rest = self.prev_ns = t_ns
        else:
            loc, shear, depth, peak = contacts[0][1], contacts[0][5], contacts[0][6], contacts[0][4]
            if self.onset is None:
                self.onset = t_ns
                dt = (t_ns - self.last_rest) / 1e9 if self.last_rest is not None else None
                self.speed = peak / dt if dt is not None and dt > 0 else 0.0
                out.append("collision" if self.speed > p.collision_speed_mm_s else "touch")
                self.anchor = self.prev_loc = loc
                self.still_since = t_ns
            else:
                dt = max((t_ns - (self.prev_ns or t_ns)) / 1e9, 1e-9)
                self.speed = norm3(loc - self.prev_loc) / dt
                if self.speed > p.rest_speed_mm_s:
                    self.still_since = None
                elif self.still_since is None:
                    self.still_since = t_ns
                self.moved = norm3(loc - self.anchor)
                sheared = norm3(shear) > p.slip_shear_ratio * max(depth, 1e-9)
                if not self.slipping and (self.moved > p.slip_mm or sheared):
                    out.append("slip")
                    self.slipping = True
                settled = self.still_since is not None and (t_ns - self.still_since) / 1e9 >= p.press_s
                if self.slipping and settled:
                    self.slipping, self.anchor = False, loc
                if not self.pressed and not self.slipping and (t_ns - self.onset) / 1e9 >= p.press_s:
                    out.append("press")
                    self.pressed = True
                self.prev_loc = loc
            self.pinch(contacts, out)
            self.prev_ns = t_ns
        start = self.onset if self.onset is not None else onset
        duration = (t_ns - start) / 1e9 if start is not None else 0.0

        def conf(value, threshold):
            return min(1.0, 0.5 + 0.5 * abs(value - threshold) / threshold)

        confidence = {"collision": conf(self.speed, p.collision_speed_mm_s),
                      "press": conf(self.speed, p.rest_speed_mm_s),
                      "slip": max(conf(self.moved, p.slip_mm), 0.5), "pat": conf(duration, p.pat_s),
                      "pinch": conf(self.approach, p.pinch_mm)}
        return out, [(confidence.get(a, 1.0), len(contacts), duration, self.speed, self.moved, self.approach)
                     for a in out]

    def pinch(self, contacts, out):
        p = self.p
        if len(contacts) < 2 or contacts[1][4] < p.pinch_peak_ratio * contacts[0][4]:
            self.pinch_d0 = self.pinch_start = self.pinch_prev = None
            return
        a, b = contacts[0][1], contacts[1][1]
        prev = self.pinch_prev
        if prev is not None:
            if norm3(a - prev[1]) + norm3(b - prev[0]) < norm3(a - prev[0]) + norm3(b - prev[1]):
                a, b = b, a
            if max(norm3(a - prev[0]), norm3(b - prev[1])) > p.pinch_jump_mm:
                prev = None
        self.pinch_prev = (a, b)
        dist = norm3(a - b)
        if prev is None or self.pinch_d0 is None:
            self.pinch_d0, self.pinch_start = dist, (a, b)
            return
        if self.pinched or self.pinch_d0 - dist <= p.pinch_mm:
            return
        a0, b0 = self.pinch_start
        u = (b0 - a0) / max(self.pinch_d0, 1e-9)
        if float((a - a0) @ u) >= p.pinch_mm / 4 and float((b0 - b) @ u) >= p.pinch_mm / 4:
            self.approach = self.pinch_d0 - dist
            out.append("pinch")
            self.pinched = True


def reference_run(mesh: SkinMesh, frames, params: ProcessingParams):
    """Per frame: (deformed, intensity, is_release, contacts, actions, evidence)."""
    free, eps = mesh.free_indices, params.epsilon_mm
    stiffness = params.modulus_mpa * mesh.node_areas / params.thickness_mm
    detector, prev, out = ReferenceActions(params.actions), np.empty(0, dtype=np.int64), []
    for t_ns, d in frames:
        norms = np.sqrt(np.einsum("ij,ij->i", d[free], d[free]))
        deformed = free[norms > eps]
        if deformed.size:
            full = np.zeros(mesh.n_nodes)
            full[free] = norms
            contacts = reference_contacts(mesh, deformed, full, d, stiffness, params.min_contact_nodes)
            row = (deformed, np.round(full[deformed], params.intensity_decimals), False, contacts)
        else:
            contacts = []
            row = (prev, np.zeros(len(prev)), bool(prev.size), contacts)
        prev = deformed
        out.append(row + detector.update(t_ns, contacts))
    return out


def scenario(mesh: SkinMesh, seed: int, n_frames: int = 160):
    """Frames at 120 Hz: held multi-finger presses (some touching), slides, pinches, rest and release."""
    rng = np.random.default_rng(seed)
    free = mesh.free_indices
    span = float(np.ptp(mesh.nodes[free], axis=0).max())
    frames, t = [], 10**9
    while len(frames) < n_frames:
        kind = rng.choice(["hold", "touching", "slide", "pinch", "rest"])
        length = int(rng.integers(3, 60))  # up to half a second: long enough for a press
        a = mesh.nodes[rng.choice(free)]
        b = mesh.nodes[rng.choice(free)]
        others = [mesh.nodes[rng.choice(free)] for _ in range(int(rng.integers(0, 4)))]
        radius = span * rng.uniform(0.03, 0.08)
        for i in range(length):
            s = i / max(length - 1, 1)
            if kind == "rest":
                d = np.zeros_like(mesh.nodes)
            elif kind == "hold":
                d = indent(mesh, [Indenter(c, span * 0.02 * (1 + 0.3 * j), radius)
                                  for j, c in enumerate([a, *others])])
            elif kind == "touching":  # two bumps a radius apart: one patch
                d = indent(mesh, [Indenter(a, span * 0.02, radius),
                                  Indenter(a + [radius, 0.0, 0.0], span * 0.015, radius)])
            elif kind == "slide":
                d = indent(mesh, [Indenter(a + s * (b - a), span * 0.02, radius, rng.normal(size=3) * 0.3)])
            else:  # pinch: two fingers moving towards each other
                mid = (a + b) / 2
                d = indent(mesh, [Indenter(a + 0.8 * s * (mid - a), span * 0.02, radius),
                                  Indenter(b + 0.8 * s * (mid - b), span * 0.018, radius)])
            if i % 3 == 2:  # now and then the same deformed set as the frame before, other values
                d = d * (1.0 + 1e-4 * rng.standard_normal())
            frames.append((t, d))
            t += 8_333_333
    return frames


def assert_identical(mesh: SkinMesh, frames, params: ProcessingParams) -> int:
    proc = FrameProcessor(mesh, params)
    n_contacts = 0
    for (t_ns, d), (deformed, intensity, release, contacts, acts, evidence) in zip(
            frames, reference_run(mesh, frames, params), strict=True):
        r = proc.process(TactileFrame(t_ns, d))
        np.testing.assert_array_equal(r.deformed_nodes, deformed, strict=True)
        np.testing.assert_array_equal(r.intensity, intensity, strict=True)
        assert r.is_release == release and r.packet_due == bool(deformed.size)
        assert len(r.contacts) == len(contacts)
        for c, (nodes, location, force, total, peak, shear, depth) in zip(r.contacts, contacts, strict=True):
            np.testing.assert_array_equal(c.nodes, nodes, strict=True)
            for got, want in ((c.location, location), (c.force, force), (c.shear, shear)):
                np.testing.assert_array_equal(got, want, strict=True)
            assert (c.intensity, c.peak, c.depth) == (total, peak, depth)
        assert r.actions == acts
        assert [(e.confidence, e.contacts, e.duration_s, e.speed_mm_s, e.moved_mm, e.approach_mm)
                for e in r.details] == evidence
        def xyz(v):
            return dict(zip("xyz", [round(float(x), 4) for x in v], strict=True))

        assert r.contact_information() == {"numOfContacts": len(contacts),
                                           "contactLocations": [xyz(c[1]) for c in contacts],
                                           "contactForces": [xyz(c[2]) for c in contacts]}
        n_contacts += len(r.contacts)
    return n_contacts


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("params", [
    ProcessingParams(epsilon_mm=0.02),
    ProcessingParams(epsilon_mm=0.05, min_contact_nodes=3, intensity_decimals=6),
], ids=["default", "min3-dec6"])
def test_pad_matches_the_reference(seed, params):
    frames = scenario(PAD, seed)
    assert assert_identical(PAD, frames, params) > len(frames) // 4


@pytest.mark.parametrize("seed", [3, 4])
def test_barrel_matches_the_reference(barrel, seed):
    frames = scenario(barrel, seed)
    assert assert_identical(barrel, frames, ProcessingParams()) > len(frames) // 4


def test_the_scenarios_cover_what_they_claim():
    """Multi-contact frames, kept splits, releases and every moving action occur (else the test is thin)."""
    proc = FrameProcessor(PAD, ProcessingParams(epsilon_mm=0.02))
    out = [proc.process(TactileFrame(t, d)) for t, d in scenario(PAD, 0, 400)]
    assert max(len(r.contacts) for r in out) >= 3
    assert sum(r.is_release for r in out) >= 2
    kept = sum(np.array_equal(a.deformed_nodes, b.deformed_nodes) for a, b in zip(out, out[1:], strict=False)
               if b.contacts)
    assert kept > 50
    assert {"touch", "release", "slip", "press", "pinch"} <= {a for r in out for a in r.actions}


@pytest.mark.parametrize("decimals", range(0, 13))
def test_rounding_is_numpys(decimals):
    values = np.random.default_rng(decimals).uniform(0, 5, 2000) ** 3
    proc = FrameProcessor(PAD, ProcessingParams(intensity_decimals=decimals))
    np.testing.assert_array_equal(proc._round(values), np.round(values, decimals), strict=True)


def test_contacts_past_the_walk_match_the_reference():
    """Above WALK_MAX_NODES deformed nodes SciPy splits the patches: the same numbers."""
    mesh = flat_pad(40, 40, pitch_mm=1.0)
    rng = np.random.default_rng(7)
    frames, t = [], 0
    for _ in range(8):
        d = indent(mesh, [Indenter(mesh.nodes[rng.choice(mesh.free_indices)], 1.0, rng.uniform(8.0, 14.0))
                          for _ in range(int(rng.integers(1, 4)))])
        frames += [(t, d), (t + 1, d * 1.001)]
        t += 2
    assert max(int((np.linalg.norm(d, axis=1) > 0.1).sum()) for _, d in frames) > 400
    assert assert_identical(mesh, frames, ProcessingParams()) >= len(frames)
