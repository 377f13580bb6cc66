import numpy as np
import pytest

from dlo_course.mesh import (
    SELECTED_RINGS, make_rod_mesh, node_of_ring, read_vtk, selected_nodes, write_vtk,
)
from dlo_course.paths import MESH_PATH


def test_counts_match_the_paper():
    mesh = make_rod_mesh()
    assert len(mesh.points) == 200
    assert len(mesh.tets) == 392
    assert len(mesh.edges) == 789
    assert len(mesh.surface_triangles) == 396


def test_every_tetrahedron_is_positively_oriented_and_the_volume_is_the_prism():
    mesh = make_rod_mesh()
    volumes = mesh.signed_volumes()
    assert np.all(volumes > 0)
    hexagonal_prism = 3 * np.sqrt(3) / 2 * 0.025 ** 2 * 1.55
    assert volumes.sum() == pytest.approx(hexagonal_prism, rel=1e-12)


def test_every_node_is_used_and_the_surface_is_closed():
    mesh = make_rod_mesh()
    assert set(np.unique(mesh.tets)) == set(range(200))
    # A closed triangulated surface: every surface edge borders exactly two surface triangles.
    tri = mesh.surface_triangles
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_layout_end_centres_and_selected_nodes():
    mesh = make_rod_mesh()
    np.testing.assert_allclose(mesh.points[0], [0, 0, 0])
    np.testing.assert_allclose(mesh.points[1], [0, 0, 1.55])
    # Selected nodes lie on the +x surface line at the heights of FACTS.md.
    heights = {26: 1.259, 15: 0.727, 23: 1.114, 18: 0.872, 8: 0.388, 29: 1.405}
    for n_nodes, rings in SELECTED_RINGS.items():
        ids = selected_nodes(n_nodes)
        assert len(ids) == n_nodes
        for ring, node in zip(rings, ids):
            x, y, z = mesh.points[node]
            assert (x, y) == pytest.approx((0.025, 0.0))
            assert z == pytest.approx(heights[ring], abs=1e-3)
    with pytest.raises(ValueError):
        selected_nodes(3)
    with pytest.raises(ValueError):
        node_of_ring(33)


def test_vtk_round_trip(tmp_path):
    mesh = make_rod_mesh()
    path = write_vtk(mesh, tmp_path / "rod.vtk")
    back = read_vtk(path)
    np.testing.assert_allclose(back.points, mesh.points)
    np.testing.assert_array_equal(back.tets, mesh.tets)
    text = path.read_text()
    assert "DATASET UNSTRUCTURED_GRID" in text and "CELL_TYPES 392" in text


def test_shipped_mesh_is_the_generated_one():
    shipped = read_vtk(MESH_PATH)
    mesh = make_rod_mesh()
    np.testing.assert_allclose(shipped.points, mesh.points)
    np.testing.assert_array_equal(shipped.tets, mesh.tets)


def test_bad_mesh_inputs(tmp_path):
    with pytest.raises(ValueError):
        make_rod_mesh(length=-1)
    with pytest.raises(FileNotFoundError):
        read_vtk(tmp_path / "missing.vtk")
    bad = tmp_path / "bad.vtk"
    bad.write_text("not a mesh")
    with pytest.raises(ValueError):
        read_vtk(bad)
