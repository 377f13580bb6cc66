"""Grading: lesson 7, deformation databases (reference: dlo_course.database)."""

import numpy as np
import pytest

from dlo_course.database import BOXES, Box, sweep_waypoints

pytestmark = pytest.mark.notebook("07_deformation_databases")


@pytest.mark.exercise("snake_order", points=2)
def test_snake_order(exercise):
    # A box with nz = 0 has a single level: the library's sweep is the descent, then the snake.
    for nx, ny in [(5, 20), (8, 22), (0, 0), (1, 2), (3, 0)]:
        box = Box("t", (-0.1, -0.2, -0.1), (0.05, 0.3, 0.0), (nx, ny, 0))
        xs = np.linspace(box.low[0], box.high[0], nx + 2)
        ys = np.linspace(box.low[1], box.high[1], ny + 2)
        got = np.asarray(exercise(xs.copy(), ys.copy()), dtype=np.float64)
        expected = sweep_waypoints(box)[1:, :2]
        assert got.shape == expected.shape, f"shape {got.shape}, expected {expected.shape}"
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    # unevenly spaced coordinates are visited in the same pattern
    got = np.asarray(exercise(np.array([0.0, 1.0, 5.0]), np.array([2.0, 3.0])))
    np.testing.assert_array_equal(got, [[0, 2], [1, 2], [5, 2], [5, 3], [1, 3], [0, 3]])


@pytest.mark.exercise("sweep_count", points=1)
def test_sweep_count(exercise):
    assert int(exercise((5, 20, 5))) == 930
    assert int(exercise((8, 22, 10))) == 2651
    for divisions in [(0, 0, 0), (1, 2, 3), (5, 21, 5), (4, 4, 0)]:
        box = Box("t", (-0.1, -0.1, -0.1), (0.1, 0.1, 0.0), divisions)
        assert int(exercise(divisions)) == box.expected_count == len(sweep_waypoints(box))


@pytest.mark.exercise("inside_box", points=1)
def test_inside_box(exercise):
    rng = np.random.default_rng(7)
    small = BOXES["small"]
    points = np.concatenate([rng.uniform(-0.5, 0.5, size=(500, 3)),
                             sweep_waypoints(BOXES["large"]),
                             [small.low, small.high]])  # corners: borders are inside
    low, high = np.asarray(small.low), np.asarray(small.high)
    got = np.asarray(exercise(points.copy(), low.copy(), high.copy()))
    expected = small.contains(points)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got.astype(bool), expected)
