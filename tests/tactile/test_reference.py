"""The fast contact finder against a straightforward reference: the same contacts, to the last bits.

The finder keeps the last split into patches and gathers only what it needs, skips the
watershed when each patch has a single maximum, reuses its split by peak while the grouping
is the same and sums every statistic in one ``reduceat`` (issues 18 and 31). The reference
does none of that: each frame from scratch, peaks by the textbook 0-dimensional persistence
(union-find over the nodes from the highest down, a node joining its highest neighbour's
peak, two peaks that meet kept apart only if the valley is significantly below the lower,
the elder rule), one array operation per statistic. Frames carry several contacts, presses
that touch (one connected patch, two peaks), presses held over several frames (the kept split
is reused), slides, pinches and releases.
"""

from __future__ import annotations

import numpy as np
import pytest

from wott_hub.tactile import (
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


def reference_segments(mesh: SkinMesh, deformed, w, floor, merge_mm, merge_ratio):
    """[(nodes ascending, base)] by persistence; ``w``: every node's norm."""
    inside = set(deformed.tolist())
    up: dict[int, int] = {}  # node -> a node of its segment (union-find), the root is the segment's peak node
    peak: dict[int, float] = {}
    base: dict[int, float] = {}

    def find(i):
        while up[i] != i:
            i = up[i]
        return i

    for i in sorted(inside, key=lambda j: (w[j], j), reverse=True):
        seen = [j for j in mesh.neighbour_lists[i] if j in up]
        if not seen:
            up[i], peak[i], base[i] = i, w[i], floor
            continue
        up[i] = find(max(seen, key=lambda j: (w[j], j)))  # the steepest way up
        for j in sorted(seen, key=lambda j: (w[j], j), reverse=True):
            a, b = find(i), find(j)
            if a == b:
                continue
            if peak[a] < peak[b] or (peak[a] == peak[b] and a > b):
                a, b = b, a
            drop = peak[b] - w[i]
            if drop <= merge_mm or drop <= merge_ratio * peak[b]:
                up[b] = a
            elif w[i] > base[b]:
                base[b] = w[i]
    groups: dict[int, list[int]] = {}
    for i in inside:
        groups.setdefault(find(i), []).append(i)
    return [(np.array(sorted(g)), base[r]) for r, g in groups.items()]


def reference_contacts(mesh: SkinMesh, d, params: ProcessingParams):
    """(nodes, location, force, intensity, peak, shear, depth, area, base) per contact, largest first."""
    w = np.linalg.norm(d, axis=1)
    eps = params.epsilon_mm
    deformed = np.flatnonzero((w > eps) & mesh.free)
    if not deformed.size:
        return []
    noise = params.below_threshold_floor * eps
    stiffness = params.modulus_mpa * mesh.node_areas / params.thickness_mm
    out = []
    merge_mm = params.merge_noise * noise
    for nodes, base in reference_segments(mesh, deformed, w, eps, merge_mm, params.merge_ratio):
        if len(nodes) < params.min_contact_nodes:
            continue
        rise = w[nodes] - eps
        normal = np.einsum("ij,ij->i", d[nodes], mesh.normals[nodes])
        shear = (d[nodes] - normal[:, None] * mesh.normals[nodes]).mean(axis=0)
        out.append((nodes, rise @ mesh.nodes[nodes] / rise.sum(), stiffness[nodes] @ d[nodes],
                    float(w[nodes].sum()), float(w[nodes].max()), shear,
                    float(np.abs(normal).mean()), float(mesh.node_areas[nodes].sum()), base))
    return sorted(out, key=lambda c: -c[3])


def scenario(mesh: SkinMesh, seed: int, n_frames: int = 160):
    """Frames at 120 Hz: held multi-finger presses (some touching), slides, pinches, rest and release."""
    rng = np.random.default_rng(seed)
    free = mesh.free_indices
    span = float(np.ptp(mesh.nodes[free], axis=0).max())
    frames, t = [], 10**9
    while len(frames) < n_frames:
        kind = rng.choice(["hold", "touching", "valley", "slide", "pinch", "rest"])
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
            elif kind == "touching":  # two bumps a radius apart: one patch, one peak
                d = indent(mesh, [Indenter(a, span * 0.02, radius),
                                  Indenter(a + [radius, 0.0, 0.0], span * 0.015, radius)])
            elif kind == "valley":  # two bumps 2.5 radii apart: one patch (above a small ε), two peaks
                d = indent(mesh, [Indenter(a, span * 0.02, radius),
                                  Indenter(a + [2.5 * radius, 0.0, 0.0], span * 0.015, radius)])
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


def assert_same_contacts(mesh: SkinMesh, frames, params: ProcessingParams) -> tuple[int, int]:
    """Every frame's contacts equal the reference's; (contacts seen, frames where a patch held two peaks)."""
    proc = FrameProcessor(mesh, params)
    n_contacts = split = 0
    for t_ns, d in frames:
        r = proc.process(TactileFrame(t_ns, d))
        want = reference_contacts(mesh, d, params)
        assert len(r.contacts) == len(want)
        for c, want_c in zip(r.contacts, want, strict=True):
            nodes, location, force, total, peak, shear, depth, area, base = want_c
            np.testing.assert_array_equal(c.nodes, nodes, strict=True)
            np.testing.assert_allclose(c.location, location, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(c.force, force, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(c.shear, shear, rtol=1e-12, atol=1e-15)
            got = (c.intensity, c.peak, c.depth, c.area)
            assert got == pytest.approx((total, peak, depth, area), rel=1e-12)
            assert c.base == pytest.approx(base, rel=1e-12)
            assert c.xyz == tuple(c.location.tolist())
        split += any(c.base > params.epsilon_mm for c in r.contacts)
        n_contacts += len(r.contacts)
    return n_contacts, split


EVERY_PEAK = dict(birth_noise=0.0)  # the reference keeps every segment: so does the processor here


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("params", [
    ProcessingParams(epsilon_mm=0.02, **EVERY_PEAK),
    ProcessingParams(epsilon_mm=0.05, min_contact_nodes=3, merge_noise=0.0, merge_ratio=0.3, **EVERY_PEAK),
], ids=["default", "min3-ratio"])
def test_pad_matches_the_reference(seed, params):
    frames = scenario(PAD, seed)
    n, split = assert_same_contacts(PAD, frames, params)
    assert n > len(frames) // 4 and split > 0


@pytest.mark.parametrize("seed", [3, 4])
def test_barrel_matches_the_reference(barrel, seed):
    frames = scenario(barrel, seed)
    n, _ = assert_same_contacts(barrel, frames, ProcessingParams(**EVERY_PEAK))
    assert n > len(frames) // 4


def test_the_scenarios_cover_what_they_claim():
    """Multi-contact frames, kept splits, patches split by peak, releases and every moving action occur
    (else the test is thin)."""
    proc = FrameProcessor(PAD, ProcessingParams(epsilon_mm=0.02))
    out = [proc.process(TactileFrame(t, d)) for t, d in scenario(PAD, 0, 400)]
    assert max(len(r.contacts) for r in out) >= 3
    assert sum(r.is_release for r in out) >= 2
    kept = sum(np.array_equal(a.deformed_nodes, b.deformed_nodes) for a, b in zip(out, out[1:], strict=False)
               if b.contacts)
    assert kept > 50
    assert sum(any(c.base > 0.02 for c in r.contacts) for r in out) > 10  # two peaks in one patch
    assert {"touch", "release", "slip", "press", "pinch"} <= {a for r in out for a in r.actions}


@pytest.mark.parametrize("decimals", range(0, 13))
def test_rounding_is_numpys(decimals):
    values = np.random.default_rng(decimals).uniform(0, 5, 2000) ** 3
    proc = FrameProcessor(PAD, ProcessingParams(intensity_decimals=decimals))
    np.testing.assert_array_equal(proc._round(values), np.round(values, decimals), strict=True)


def test_contacts_past_the_walk_match_the_reference():
    """Above WALK_MAX_NODES deformed nodes SciPy splits the patches: the same contacts."""
    mesh = flat_pad(40, 40, pitch_mm=1.0)
    rng = np.random.default_rng(7)
    frames, t = [], 0
    for _ in range(8):
        d = indent(mesh, [Indenter(mesh.nodes[rng.choice(mesh.free_indices)], 1.0, rng.uniform(8.0, 14.0))
                          for _ in range(int(rng.integers(1, 4)))])
        frames += [(t, d), (t + 1, d * 1.001)]
        t += 2
    assert max(int((np.linalg.norm(d, axis=1) > 0.1).sum()) for _, d in frames) > 400
    n, _ = assert_same_contacts(mesh, frames, ProcessingParams(**EVERY_PEAK))
    assert n >= len(frames)
