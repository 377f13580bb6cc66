import numpy as np
import pytest

from dlo_course.mesh import (
    SELECTED_RINGS, TetMesh, make_rod_mesh, node_of_ring, read_vtk, selected_nodes, write_vtk,
)
from dlo_course.paths import MESH_PATH


CUTS = ("course", "mirrored")


@pytest.mark.parametrize("cuts", CUTS)
def test_counts_match_the_paper(cuts):
    mesh = make_rod_mesh(cuts=cuts)
    assert len(mesh.points) == 200
    assert len(mesh.tets) == 392
    assert len(mesh.edges) == 789
    assert len(mesh.surface_triangles) == 396


@pytest.mark.parametrize("cuts", CUTS)
def test_every_tetrahedron_is_positively_oriented_and_the_volume_is_the_prism(cuts):
    mesh = make_rod_mesh(cuts=cuts)
    volumes = mesh.signed_volumes()
    assert np.all(volumes > 0)
    hexagonal_prism = 3 * np.sqrt(3) / 2 * 0.025 ** 2 * 1.55
    assert volumes.sum() == pytest.approx(hexagonal_prism, rel=1e-12)


@pytest.mark.parametrize("cuts", CUTS)
def test_every_node_is_used_and_the_surface_is_closed(cuts):
    mesh = make_rod_mesh(cuts=cuts)
    assert set(np.unique(mesh.tets)) == set(range(200))
    # A closed triangulated surface: every surface edge borders exactly two surface triangles.
    tri = mesh.surface_triangles
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)


@pytest.mark.parametrize("cuts", CUTS)
def test_the_mesh_is_conforming(cuts):
    # Neighbouring tetrahedra cut their shared quad the same way: every face is shared by at
    # most two tetrahedra, and every face that is not on the surface by exactly two.
    mesh = make_rod_mesh(cuts=cuts)
    t = mesh.tets
    faces = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]])
    _, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    assert set(counts) == {1, 2}
    assert (counts == 2).sum() == (4 * 392 - 396) // 2


def _tet_set(tets):
    return set(map(tuple, np.sort(tets, axis=1)))


def _reflected_about_ring(mesh, ring):
    """The mesh's tetrahedra with every node replaced by its mirror image across ``ring``'s
    plane (the end centres 0 and 1 swap when ``ring`` is the middle one)."""
    z0 = ring * 1.55 / 32
    image = mesh.points * [1, 1, -1] + [0, 0, 2 * z0]
    distance = np.linalg.norm(image[:, None] - mesh.points[None], axis=2)
    return distance.argmin(axis=1)[mesh.tets], distance.min(axis=1).max()


def test_mirrored_cuts_make_each_layer_the_mirror_image_of_its_neighbour():
    # The whole rod is symmetric about its middle ring, ends included.
    mirrored = make_rod_mesh(cuts="mirrored")
    image, miss = _reflected_about_ring(mirrored, 16)
    assert miss < 1e-12
    assert _tet_set(image) == _tet_set(mirrored.tets)
    # The course's cuts repeat the same layer: the reflection is another mesh.
    course = make_rod_mesh()
    image, _ = _reflected_about_ring(course, 16)
    assert _tet_set(image) != _tet_set(course.tets)
    # Inner layers: the layer above ring k (rings k, k+1) reflected across ring k is exactly
    # the layer below it (rings k-1, k), for every k, and in the course's mesh never.
    def layer(mesh, k):
        rings = (mesh.tets - 2) // 6
        inside = np.all((mesh.tets >= 2) & (rings >= k) & (rings <= k + 1), axis=1)
        return mesh.tets[inside]
    for k in range(2, 31):
        for mesh, same in ((mirrored, True), (course, False)):
            image, _ = _reflected_about_ring(TetMesh(mesh.points, layer(mesh, k)), k)
            assert (_tet_set(image) == _tet_set(layer(mesh, k - 1))) is same, (k, same)


def test_unknown_cuts_are_refused():
    with pytest.raises(ValueError, match="cuts"):
        make_rod_mesh(cuts="gmsh")


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
