"""Grading: lesson 5, soft bodies (reference: dlo_course.mesh, dlo_course.simulation).

The meshes are built here and sent to the sandbox as arrays.
"""

import numpy as np
import pytest

from dlo_course.mesh import TetMesh, make_rod_mesh
from dlo_course.simulation import lame_parameters

pytestmark = pytest.mark.notebook("05_soft_bodies_in_pybullet")


def random_meshes():
    """The paper's rod, a thin rod of another size, and random (partly inverted) tetrahedra,
    one set of them fresh at every grading."""
    rng = np.random.default_rng(5)
    yield make_rod_mesh()
    yield make_rod_mesh(length=0.4, radius=0.01)
    points = rng.normal(size=(30, 3))
    tets = np.array([rng.choice(30, 4, replace=False) for _ in range(25)])
    yield TetMesh(points, tets)
    fresh = np.random.default_rng()  # and a mesh drawn afresh at every grading
    n = int(fresh.integers(5, 60))
    tets = np.array([fresh.choice(n, 4, replace=False) for _ in range(int(fresh.integers(1, 80)))])
    yield TetMesh(fresh.uniform(-1, 1, size=(n, 3)), tets)


TWO = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])  # two tetrahedra sharing the face (1, 2, 3)


def probe_each(fn, inputs):
    """fn(*args) for every args of inputs, as arrays."""
    return [np.asarray(fn(*[np.array(a) for a in args])) for args in inputs]


def as_row_set(rows, width):
    rows = np.asarray(rows)
    assert rows.ndim == 2 and rows.shape[1] == width, \
        f"expected shape (n, {width}), got {rows.shape}"
    return {tuple(sorted(int(i) for i in row)) for row in rows}


def check_same_rows(got, meshes, reference, width, noun):
    for rows, mesh in zip(got, meshes, strict=True):
        expected = reference(mesh)
        assert len(rows) == len(expected), f"{len(rows)} {noun}, expected {len(expected)}"
        assert as_row_set(rows, width) == as_row_set(expected, width)


@pytest.mark.exercise("tet_signed_volumes", points=2,
                      reference="dlo_course.mesh.TetMesh.signed_volumes")
def test_tet_signed_volumes(student):
    meshes = list(random_meshes())
    got = student.run(probe_each, [(m.points, m.tets) for m in meshes])
    for volumes, mesh in zip(got, meshes, strict=True):
        expected = mesh.signed_volumes()
        assert volumes.shape == expected.shape
        np.testing.assert_allclose(volumes.astype(np.float64), expected, rtol=1e-9, atol=1e-15)


@pytest.mark.exercise("mesh_edges", points=2, reference="dlo_course.mesh.TetMesh.edges")
def test_mesh_edges(student):
    meshes = list(random_meshes())
    got = student.run(probe_each, [(m.tets,) for m in meshes])
    check_same_rows(got, meshes, lambda mesh: mesh.edges, 2, "edges")
    assert len(got[0]) == 789


@pytest.mark.exercise("surface_triangles", points=2,
                      reference="dlo_course.mesh.TetMesh.surface_triangles")
def test_surface_triangles(student):
    meshes = [*random_meshes(), TetMesh(np.zeros((5, 3)), TWO)]
    got = student.run(probe_each, [(m.tets,) for m in meshes])
    check_same_rows(got, meshes, lambda mesh: mesh.surface_triangles, 3, "faces")


LAME_CASES = [(2.5e6, 0.3), (1.0e5, 0.45), (7.0e10, 0.0), (3.0, -0.5)]


def probe_lame_parameters(fn):
    return [[float(x) for x in fn(e, nu)] for e, nu in LAME_CASES]


@pytest.mark.exercise("lame_parameters", points=1,
                      reference="dlo_course.simulation.lame_parameters")
def test_lame_parameters(student):
    got = student.run(probe_lame_parameters)
    np.testing.assert_allclose(np.asarray(got, dtype=float),
                               np.asarray(probe_lame_parameters(lame_parameters)), rtol=1e-12)


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_substep", points=1)
def test_prediction_substep(written_answer):
    written_answer.check()
