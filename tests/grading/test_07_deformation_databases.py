"""Grading: lesson 7, deformation databases (reference: dlo_course.database)."""

import numpy as np
import pytest

from dlo_course.database import BOXES, Box, authors_sweep

pytestmark = pytest.mark.notebook("07_deformation_databases")

# The paper's two boxes, tiny ones, and odd and even numbers of y lines.
TEST_BOXES = [
    BOXES["small"],
    BOXES["large"],
    Box("tiny", (-0.02, -0.02, -0.02), (0.02, 0.02, 0.0), (1, 1, 1)),
    Box("one", (-0.01, -0.01, -0.01), (0.01, 0.01, 0.0), (0, 0, 0)),
    Box("flat", (-0.1, -0.2, -0.1), (0.05, 0.3, 0.0), (3, 0, 2)),
    Box("uneven", (-0.12, -0.3, -0.2), (0.04, 0.1, 0.0), (2, 5, 3)),
    Box("even", (-0.1, -0.25, -0.25), (0.05, 0.25, 0.0), (5, 21, 5)),
]


def levels_of(box: Box):
    """The library's sweep cut into levels: (rx, ry, direction, moves) for each level."""
    sweep = authors_sweep(box)
    rx, ry, rz = (n + 1 for n in box.divisions)
    start = int(np.count_nonzero(~sweep.recorded))
    per_level = box.expected_count // rz
    for level in range(rz):
        moves = sweep.moves[start + level * per_level:start + (level + 1) * per_level]
        yield rx, ry, (1 if level % 2 == 0 else -1), moves


@pytest.mark.exercise("level_moves", points=2)
def test_level_moves(exercise):
    for box in TEST_BOXES:
        for rx, ry, direction, expected in levels_of(box):
            got = np.asarray(exercise(rx, ry, box.steps.copy(), direction), dtype=np.float64)
            assert got.shape == expected.shape, \
                f"{box.name} box, direction {direction}: shape {got.shape}, expected {expected.shape}"
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12,
                                       err_msg=f"{box.name} box, direction {direction}")
    # Steps given as a tuple, made-up numbers: the pattern does not depend on the box.
    got = np.asarray(exercise(2, 3, (1.0, 2.0, 3.0), -1), dtype=np.float64)
    x, y, z = [1.0, 0, 0], [0, -2.0, 0], [0, 0, -3.0]
    back = [-1.0, 0, 0]
    np.testing.assert_allclose(got, [x, x, y, back, back, y] * 2 + [z], rtol=0, atol=1e-12)


@pytest.mark.exercise("sweep_count", points=1)
def test_sweep_count(exercise):
    assert int(exercise((5, 20, 5))) == 930
    assert int(exercise((8, 22, 10))) == 2651
    for box in TEST_BOXES:
        expected = box.expected_count
        assert expected == int(authors_sweep(box).recorded.sum())
        assert int(exercise(tuple(box.divisions))) == expected, f"divisions {box.divisions}"
    for divisions in [(4, 4, 0), (0, 3, 1), (7, 2, 4)]:
        box = Box("t", (-0.1, -0.1, -0.1), (0.1, 0.1, 0.0), divisions)
        assert int(exercise(divisions)) == box.expected_count == authors_sweep(box).recorded.sum()


@pytest.mark.exercise("inside_box", points=1)
def test_inside_box(exercise):
    rng = np.random.default_rng(7)
    small = BOXES["small"]
    points = np.concatenate([rng.uniform(-0.5, 0.5, size=(500, 3)),
                             authors_sweep(BOXES["large"]).offsets,
                             [small.low, small.high]])  # corners: borders are inside
    low, high = np.asarray(small.low), np.asarray(small.high)
    got = np.asarray(exercise(points.copy(), low.copy(), high.copy()))
    expected = small.contains(points)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got.astype(bool), expected)
