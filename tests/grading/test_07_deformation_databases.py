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


def random_box(rng, name):
    """A fresh box: walls around the initial tip (the top at its height), random divisions."""
    low = (rng.uniform(-0.2, -0.01), rng.uniform(-0.4, -0.01), rng.uniform(-0.3, -0.05))
    high = (rng.uniform(0.0, 0.1), rng.uniform(0.01, 0.4), 0.0)
    divisions = (int(rng.integers(0, 9)), int(rng.integers(0, 13)), int(rng.integers(0, 6)))
    return Box(name, low, high, divisions)


def as_data(box):
    return (box.name, tuple(map(float, box.low)), tuple(map(float, box.high)),
            tuple(map(int, box.divisions)))


def sweep_cases(rng):
    """(box, region) pairs: the paper's boxes against each other and themselves, a region
    whose walls are the sweep's own extreme offsets (every record on or inside a wall), the
    test boxes, and fresh random boxes and regions."""
    small, large = BOXES["small"], BOXES["large"]
    offsets = authors_sweep(small).offsets
    tight = Box("tight", tuple(offsets.min(axis=0)), tuple(offsets.max(axis=0)), (1, 1, 1))
    yield from [(large, small), (small, small), (small, large), (small, tight)]
    for box in TEST_BOXES[2:]:
        yield box, small
    for k in range(6):
        yield random_box(rng, f"random{k}"), random_box(rng, f"region{k}")


def probe_sweep_offsets_inside(fn, cases):
    from dlo_course.database import Box as SandboxBox

    out = []
    for box, region in cases:
        offsets, inside = fn(SandboxBox(*box), SandboxBox(*region))
        out.append((np.asarray(offsets, dtype=np.float64), np.asarray(inside)))
    return out


@pytest.mark.exercise("sweep_offsets_inside", points=2,
                      reference=("dlo_course.database.authors_sweep",
                                 "dlo_course.database.Box.contains"))
def test_sweep_offsets_inside(student):
    rng = np.random.default_rng()  # fresh boxes at every grading
    cases = list(sweep_cases(rng))
    got = student.run(probe_sweep_offsets_inside,
                      [(as_data(box), as_data(region)) for box, region in cases])
    for (offsets, inside), (box, region) in zip(got, cases, strict=True):
        where = f"the sweep of {box.name} {box.divisions} against {region.name}"
        want = authors_sweep(box).offsets
        assert len(want) == box.expected_count
        assert offsets.shape == want.shape, f"{where}: offsets {offsets.shape}, expected {want.shape}"
        np.testing.assert_allclose(offsets, want, rtol=0, atol=1e-12, err_msg=where)
        assert inside.shape == (len(want),), f"{where}: inside has shape {inside.shape}"
        # judged on the student's own offsets (equal to the library's to 1e-12), borders included
        np.testing.assert_array_equal(inside.astype(bool), region.contains(offsets), err_msg=where)
    assert [len(o) for o, _ in got[:2]] == [2651, 930]
    assert got[3][1].all()  # every record of the small sweep lies in its own extreme offsets


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_inside", points=1)
def test_prediction_inside(written_answer):
    written_answer.check()
