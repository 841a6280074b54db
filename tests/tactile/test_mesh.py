import numpy as np
import pytest

from wott_hub.tactile import (
    MeshError,
    SkinMesh,
    barrel,
    cylinder,
    flat_pad,
    load_taclink_barrel,
    taclink_barrel,
)


@pytest.fixture(scope="module")
def taclink(shared_data):
    d = shared_data / "taclink"
    return load_taclink_barrel(d / "barrel_skin.vtk", d / "node_idx.csv", d / "label_idx.csv")


def test_barrel_counts(taclink):
    assert taclink.n_nodes == 707
    assert taclink.n_cells == 1374
    assert taclink.cells.shape == (1374, 3)
    assert taclink.free.sum() == 585
    assert len(taclink.clamped_indices) == 122


def test_barrel_free_nodes_match_fe_labels(taclink, shared_data):
    fe = np.loadtxt(shared_data / "taclink/node_idx.csv", skiprows=1, dtype=int)
    labels = np.loadtxt(shared_data / "taclink/label_idx.csv", skiprows=1, delimiter=",", usecols=0,
                        dtype=int)
    assert set(fe[taclink.free]) == set(labels)
    # the data README: the clamped nodes are the 122 near the rims
    z = taclink.nodes[:, 2]
    np.testing.assert_array_equal(~taclink.free, (z < 21) | (z > 240))


def test_shipped_copy_equals_reference(taclink):
    shipped = taclink_barrel()
    np.testing.assert_array_equal(shipped.nodes, taclink.nodes)
    np.testing.assert_array_equal(shipped.cells, taclink.cells)
    np.testing.assert_array_equal(shipped.free, taclink.free)


def test_barrel_cells_valid(taclink):
    c = taclink.cells
    assert c.min() >= 0 and c.max() < taclink.n_nodes
    assert all(len(set(row)) == 3 for row in c.tolist())
    assert (taclink.cell_areas > 1e-6).all()
    # a manifold surface: every edge is shared by one (rim) or two cells
    pairs = np.sort(np.concatenate([c[:, [0, 1]], c[:, [1, 2]], c[:, [2, 0]]]), axis=1)
    _, counts = np.unique(pairs, axis=0, return_counts=True)
    assert set(counts.tolist()) <= {1, 2}
    assert len(taclink.edges) == len(counts)
    # consistent winding: an interior edge is walked in opposite directions by its two cells
    directed = np.concatenate([c[:, [0, 1]], c[:, [1, 2]], c[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)


def test_barrel_normals_point_outward(taclink):
    p = taclink.nodes
    radial = np.column_stack([p[:, 0], p[:, 1], np.zeros(len(p))])
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert (np.einsum("ij,ij->i", taclink.normals, radial) > 0.5).all()
    np.testing.assert_allclose(np.linalg.norm(taclink.normals, axis=1), 1.0)


def test_barrel_geometry_matches_readme(taclink):
    z = taclink.nodes[:, 2]
    r = np.hypot(taclink.nodes[:, 0], taclink.nodes[:, 1])
    assert z.min() == pytest.approx(0, abs=1e-6) and z.max() == pytest.approx(260)
    assert r[np.isclose(z, 0, atol=1e-6)].mean() == pytest.approx(36.28, abs=0.05)
    assert r.max() == pytest.approx(53.36, abs=0.3)


def test_adjacency_is_symmetric_and_matches_edges(taclink):
    a = taclink.adjacency
    assert (a != a.T).nnz == 0
    assert a.nnz == 2 * len(taclink.edges)
    n0 = taclink.neighbours(300)
    assert len(n0) >= 3 and 300 not in n0


def test_flat_pad():
    m = flat_pad(7, 9, pitch_mm=2.0)
    assert m.n_nodes == 63 and m.n_cells == 48 and m.cells.shape[1] == 4
    np.testing.assert_allclose(m.normals, np.tile([0, 0, 1.0], (63, 1)))
    assert m.free.sum() == 5 * 7
    assert m.node_areas.sum() == pytest.approx(12 * 16)
    assert len(m.edges) == 7 * 8 + 9 * 6
    assert tuple(m.nodes[2 * 9 + 3]) == (6.0, 4.0, 0.0)  # node (r, c) = r * cols + c


@pytest.mark.parametrize("make", [lambda: barrel(30, 45, 200), lambda: cylinder(40, 120)])
def test_revolution_generators_face_outward(make):
    m = make()
    radial = np.column_stack([m.nodes[:, 0], m.nodes[:, 1], np.zeros(m.n_nodes)])
    assert (np.einsum("ij,ij->i", m.normals, radial) > 0).all()
    assert 0 < m.free.sum() < m.n_nodes


def test_barrel_profile():
    m = barrel(30, 45, 200, rings=21, rays=16)
    r = np.hypot(m.nodes[:, 0], m.nodes[:, 1])
    z = m.nodes[:, 2]
    assert r[z == 0].mean() == pytest.approx(30) and r[np.isclose(z, 100)].mean() == pytest.approx(45)


@pytest.mark.parametrize(
    "nodes,cells,free,match",
    [
        (np.zeros((3, 2)), [[0, 1, 2]], [True] * 3, "N, 3"),
        (np.full((3, 3), np.nan), [[0, 1, 2]], [True] * 3, "NaN"),
        (np.eye(3), [[0, 1, 5]], [True] * 3, "indices"),
        (np.eye(3), [[0, 1, 1]], [True] * 3, "repeats"),
        (np.eye(3), [[0, 1]], [True] * 3, "triangles"),
        (np.eye(3), [[0, 1, 2]], [True] * 2, "mask"),
    ],
)
def test_bad_meshes_are_refused(nodes, cells, free, match):
    with pytest.raises(MeshError, match=match):
        SkinMesh(nodes, np.asarray(cells), np.asarray(free))


def test_bad_generator_arguments():
    with pytest.raises(MeshError):
        flat_pad(1, 5)
    with pytest.raises(MeshError):
        barrel(-1, 10, 10)


def test_mesh_arrays_are_read_only():
    m = flat_pad(3, 3)
    with pytest.raises(ValueError):
        m.nodes[0, 0] = 1.0
