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


def probe_each(fn, cases):
    """fn(*args) for each args of cases, as float64 arrays."""
    return [np.asarray(fn(*args), dtype=np.float64) for args in cases]


@pytest.mark.exercise("level_moves", points=2, reference="dlo_course.database.authors_sweep")
def test_level_moves(student):
    cases, expected = [], []
    for box in TEST_BOXES:
        for rx, ry, direction, moves in levels_of(box):
            cases.append((rx, ry, np.array(box.steps), direction))
            expected.append((box.name, direction, moves))
    # Steps given as a tuple, made-up numbers: the pattern does not depend on the box.
    cases.append((2, 3, (1.0, 2.0, 3.0), -1))
    x, y, z = [1.0, 0, 0], [0, -2.0, 0], [0, 0, -3.0]
    back = [-1.0, 0, 0]
    expected.append(("made-up", -1, np.array([x, x, y, back, back, y] * 2 + [z])))
    got = student.run(probe_each, cases)
    for moves, (name, direction, want) in zip(got, expected, strict=True):
        assert moves.shape == want.shape, \
            f"{name} box, direction {direction}: shape {moves.shape}, expected {want.shape}"
        np.testing.assert_allclose(moves, want, rtol=0, atol=1e-12,
                                   err_msg=f"{name} box, direction {direction}")


@pytest.mark.exercise("sweep_count", points=1, reference="dlo_course.database.authors_sweep")
def test_sweep_count(student):
    divisions = [(5, 20, 5), (8, 22, 10)] + [tuple(box.divisions) for box in TEST_BOXES] \
        + [(4, 4, 0), (0, 3, 1), (7, 2, 4)]
    expected = []
    for d in divisions:
        box = Box("t", (-0.1, -0.1, -0.1), (0.1, 0.1, 0.0), d)
        expected.append(int(authors_sweep(box).recorded.sum()))
        assert expected[-1] == box.expected_count
    assert expected[:2] == [930, 2651]
    got = student.run(probe_each, [(d,) for d in divisions])
    for count, want, d in zip(got, expected, divisions, strict=True):
        assert count.size == 1 and int(count) == want, f"divisions {d}: {count}, expected {want}"


@pytest.mark.exercise("inside_box", points=1, reference="dlo_course.database.Box.contains")
def test_inside_box(student):
    rng = np.random.default_rng(7)
    small = BOXES["small"]
    points = np.concatenate([rng.uniform(-0.5, 0.5, size=(500, 3)),
                             authors_sweep(BOXES["large"]).offsets,
                             [small.low, small.high]])  # corners: borders are inside
    low, high = np.asarray(small.low), np.asarray(small.high)
    (got,) = student.run(probe_each, [(points, low, high)])
    expected = small.contains(points)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got.astype(bool), expected)
