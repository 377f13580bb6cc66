"""Grading: lesson 5, soft bodies (reference: dlo_course.mesh, dlo_course.simulation)."""

import numpy as np
import pytest

from dlo_course.mesh import TetMesh, make_rod_mesh
from dlo_course.simulation import lame_parameters

pytestmark = pytest.mark.notebook("05_soft_bodies_in_pybullet")


def random_meshes():
    """The paper's rod, a thin rod of another size, and random (partly inverted) tetrahedra."""
    rng = np.random.default_rng(5)
    yield make_rod_mesh()
    yield make_rod_mesh(length=0.4, radius=0.01)
    points = rng.normal(size=(30, 3))
    tets = np.array([rng.choice(30, 4, replace=False) for _ in range(25)])
    yield TetMesh(points, tets)


def as_row_set(rows, width):
    rows = np.asarray(rows)
    assert rows.ndim == 2 and rows.shape[1] == width, \
        f"expected shape (n, {width}), got {rows.shape}"
    return {tuple(sorted(int(i) for i in row)) for row in rows}


def assert_same_rows_on_every_mesh(exercise, reference, width, noun):
    """exercise(tets) gives the rows of ``reference(mesh)`` (in any order) on every mesh."""
    for mesh in random_meshes():
        got = np.asarray(exercise(mesh.tets.copy()))
        expected = reference(mesh)
        assert len(got) == len(expected), f"{len(got)} {noun}, expected {len(expected)}"
        assert as_row_set(got, width) == as_row_set(expected, width)


@pytest.mark.exercise("tet_signed_volumes", points=2)
def test_tet_signed_volumes(exercise):
    for mesh in random_meshes():
        got = np.asarray(exercise(mesh.points.copy(), mesh.tets.copy()), dtype=np.float64)
        expected = mesh.signed_volumes()
        assert got.shape == expected.shape
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-15)


@pytest.mark.exercise("mesh_edges", points=2)
def test_mesh_edges(exercise):
    assert_same_rows_on_every_mesh(exercise, lambda mesh: mesh.edges, 2, "edges")
    assert len(exercise(make_rod_mesh().tets)) == 789


@pytest.mark.exercise("surface_triangles", points=2)
def test_surface_triangles(exercise):
    assert_same_rows_on_every_mesh(exercise, lambda mesh: mesh.surface_triangles, 3, "faces")
    two = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])  # two tetrahedra sharing the face (1, 2, 3)
    assert as_row_set(exercise(two), 3) == as_row_set(TetMesh(np.zeros((5, 3)), two)
                                                      .surface_triangles, 3)


@pytest.mark.exercise("lame_parameters", points=1)
def test_lame_parameters(exercise):
    for e, nu in [(2.5e6, 0.3), (1.0e5, 0.45), (7.0e10, 0.0), (3.0, -0.5)]:
        np.testing.assert_allclose(np.asarray(exercise(e, nu), dtype=float),
                                   lame_parameters(e, nu), rtol=1e-12)
