"""Contact patches: the Python walk and SciPy's search agree, and each patch's numbers are its own."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components

from wott_hub.tactile import WinklerForceModel, contacts, find_contacts, flat_pad

BIG = flat_pad(30, 30, pitch_mm=2.0)  # 900 nodes: deformed sets on both sides of WALK_MAX_NODES


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Two labellings of the same nodes describe the same grouping (labels may be renamed)."""
    return len(set(zip(a.tolist(), b.tolist(), strict=True))) == len(set(a.tolist())) == len(set(b.tolist()))


@settings(max_examples=40, deadline=None)
@given(mask=st.lists(st.booleans(), min_size=BIG.n_nodes, max_size=BIG.n_nodes), walk=st.booleans())
def test_both_searches_find_scipys_components(mask, walk):
    nodes = np.flatnonzero(mask)
    if nodes.size == 0:
        return
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(contacts, "WALK_MAX_NODES", BIG.n_nodes if walk else 0)
        grouped, sizes = contacts.group_patches(BIG, nodes)
    ref_n, ref = connected_components(BIG.adjacency[nodes][:, nodes], directed=False)
    assert len(sizes) == ref_n and sizes.sum() == len(nodes)
    labels = np.repeat(np.arange(len(sizes)), sizes)
    assert same_partition(labels, ref[np.searchsorted(nodes, grouped)])
    firsts = grouped[np.cumsum(sizes) - sizes]
    assert np.all(np.diff(firsts) > 0)  # patches in order of their smallest node
    for patch in np.split(grouped, np.cumsum(sizes)[:-1]):
        assert np.all(np.diff(patch) > 0)  # ascending within each


def test_each_patch_gets_its_own_statistics():
    """Three patches of different sizes, one below min_nodes: every number equals the patch computed alone."""
    mesh = flat_pad(20, 20, pitch_mm=2.0)
    d = np.zeros((mesh.n_nodes, 3))
    rng = np.random.default_rng(3)
    patches = [np.array([42, 43, 62, 63, 82]), np.array([250, 251]), np.array([317])]
    for p in patches:
        d[p] = rng.uniform(-1, 1, (len(p), 3))
    deformed = np.sort(np.concatenate(patches))
    intensity = np.linalg.norm(d, axis=1)
    force = WinklerForceModel(mesh, 0.1, 3.0)
    found = find_contacts(mesh, deformed, intensity, d, force, min_nodes=2)
    assert sorted(len(c.nodes) for c in found) == [2, 5]  # the single node is noise
    assert [c.intensity for c in found] == sorted((c.intensity for c in found), reverse=True)
    for c in found:
        p = next(p for p in patches if set(p) == set(c.nodes.tolist()))
        w, n = intensity[p], mesh.normals[p]
        normal = np.einsum("ij,ij->i", d[p], n)
        np.testing.assert_allclose(c.location, w @ mesh.nodes[p] / w.sum())
        np.testing.assert_allclose(c.force, force.force(p, d))
        np.testing.assert_allclose(c.shear, (d[p] - normal[:, None] * n).mean(axis=0), atol=1e-15)
        assert c.intensity == pytest.approx(w.sum()) and c.peak == pytest.approx(w.max())
        assert c.depth == pytest.approx(np.abs(normal).mean())
        assert np.all(np.diff(c.nodes) > 0)


def test_neighbour_lists_match_the_adjacency():
    a = BIG.adjacency
    for node in (0, 31, 450, BIG.n_nodes - 1):
        assert list(BIG.neighbour_lists[node]) == a.indices[a.indptr[node]:a.indptr[node + 1]].tolist()
