"""Deformation databases: the authors' sweep, the settled protocol, the paper's test goals."""

import numpy as np
import pytest

from dlo_course import load_database
from dlo_course.database import (AUTHORS_SWEEP, BOXES, SETTLED, SWEEP_STEPS_BEFORE, Box,
                                 _record_authors_sweep, authors_sweep, generate_database,
                                 resolve_goals, save_database, settled_waypoints, sweep_levels)
from dlo_course.simulation import RodScene


def test_the_authors_sweep_of_a_tiny_box_move_by_move():
    # Divisions (1, 1, 1): r = 2 lines per axis, steps (0.02, 0.02, 0.01).
    box = Box("tiny", (-0.02, -0.02, -0.02), (0.02, 0.02, 0.0), (1, 1, 1))
    x, y, z = (0.02, 0, 0), (0, 0.02, 0), (0, 0, -0.01)
    minus = lambda v: tuple(-c for c in v)  # noqa: E731
    expected = [
        (minus(x), False), (minus(y), False),                  # to the start corner
        (x, True), (x, True), (y, True), (minus(x), True), (minus(x), True), (y, True),
        (z, True),                                             # level 0 ends one step down
        (x, True), (x, True), (minus(y), True), (minus(x), True), (minus(x), True),
        (minus(y), True), (z, True),                           # level 1 snakes back
    ]
    sweep = authors_sweep(box)
    np.testing.assert_allclose(sweep.moves, [m for m, _ in expected], atol=1e-15)
    assert sweep.recorded.tolist() == [r for _, r in expected]
    assert len(sweep.offsets) == box.expected_count == 14
    # The first recorded shape is one x step from the start corner, at the initial height.
    np.testing.assert_allclose(sweep.offsets[0], (0.0, -0.02, 0.0), atol=1e-15)


@pytest.mark.parametrize("name,count,start_moves", [("small", 930, (4, 11)),
                                                    ("large", 2651, (7, 12))])
def test_sweep_counts_and_levels(name, count, start_moves):
    box = BOXES[name]
    sweep = authors_sweep(box)
    assert sweep.recorded.sum() == box.expected_count == count
    assert len(settled_waypoints(box)) == count  # the settled protocol: same count
    # The unrecorded start: x moves first, then y moves, then nothing but recorded moves.
    n_x, n_y = start_moves
    assert not sweep.recorded[:n_x + n_y].any() and sweep.recorded[n_x + n_y:].all()
    assert np.all(sweep.moves[:n_x, 0] < 0) and np.all(sweep.moves[n_x:n_x + n_y, 1] < 0)
    # The first level is at the initial height; each level ends with a recorded z move.
    offsets, levels = sweep.offsets, sweep_levels(box)
    per_level = count // (box.divisions[2] + 1)
    assert per_level == {"small": 155, "large": 241}[name]
    assert np.all(offsets[:per_level - 1, 2] == 0.0)
    np.testing.assert_allclose(offsets[per_level - 1:: per_level, 2],
                               -box.steps[2] * np.arange(1, box.divisions[2] + 2), atol=1e-12)
    assert levels[0] == 0 and levels[-1] == box.divisions[2] and np.all(np.diff(levels) >= 0)
    # The grid starts from the initial tip, so it may overshoot the box by under one step.
    outside = np.abs(offsets - np.clip(offsets, box.low, box.high))
    assert np.all(outside < box.steps)


class CountingScene(RodScene):
    """The real scene, counting its physics steps."""

    steps = 0

    def step_physics(self, n: int = 1) -> None:
        self.steps += n
        super().step_physics(n)


@pytest.mark.slow
def test_two_physics_steps_per_recorded_move():
    scene = CountingScene()
    counts = []
    try:
        _record_authors_sweep(scene, BOXES["small"], limit=2,
                              record=lambda before, seconds: counts.append(scene.steps))
    finally:
        scene.close()
    start = SWEEP_STEPS_BEFORE + 4 + 11  # 3 steps, then one per start move
    assert counts == [start + 2, start + 4]


@pytest.mark.slow
def test_a_regenerated_prefix_equals_the_shipped_small_database(tmp_path):
    path = generate_database("small", out=tmp_path / "prefix.npz", limit=20, progress=False)
    prefix, shipped = load_database(path), load_database("small")
    assert prefix.protocol == shipped.protocol == AUTHORS_SWEEP
    assert len(prefix) == 20 and not bool(prefix.meta["complete"])
    np.testing.assert_allclose(prefix.nodes, shipped.nodes[:20], atol=1e-6)
    np.testing.assert_allclose(prefix.tip, shipped.tip[:20], atol=1e-6)


def test_the_settled_protocol_is_still_selectable(tmp_path):
    path = generate_database("small", out=tmp_path / "tiny.npz", limit=2, settle_steps=1,
                             progress=False)
    db = load_database(path)
    assert db.protocol == SETTLED and int(db.meta["settle_steps"]) == 1
    assert len(db) == 2 and not bool(db.meta["complete"])
    np.testing.assert_allclose(db.tip - db.meta["initial_tip"],
                               settled_waypoints(BOXES["small"])[:2], atol=0.005)


@pytest.mark.parametrize("name", ["small", "large"])
def test_shipped_databases(name):
    db = load_database(name)
    box = BOXES[name]
    assert db.protocol == AUTHORS_SWEEP and bool(db.meta["complete"])
    assert db.tip.shape == (box.expected_count, 3) and db.nodes.shape == (len(db), 200, 3)
    for n in (2, 4, 6):
        assert db.goals(n).shape == (len(db), n, 3)
    np.testing.assert_allclose(db.meta["offsets"], authors_sweep(box).offsets)
    # Each move starts from where the tip is, after only 6 ms of physics for the last one, so
    # the tip lags behind its nominal grid: by up to 5.5 cm in the small box and 10.4 cm in
    # the large one (larger y steps), which is what makes the authors' rod lean to +y.
    drift = np.abs(db.tip - db.meta["initial_tip"] - db.meta["offsets"])
    assert 0.01 < np.max(drift) < 0.12
    # The rod is held at both ends: node 0 on the ground, node 1 at the tip.
    np.testing.assert_allclose(db.nodes[:, 0, 2], 0.0, atol=0.005)
    assert np.max(np.linalg.norm(db.nodes[:, 1] - db.tip, axis=1)) < 0.1


def test_the_first_round_settled_databases_are_kept():
    for name, count in (("small_settled", 930), ("large_settled", 2651)):
        db = load_database(name)
        assert db.protocol == SETTLED and len(db) == count
        with pytest.raises(ValueError, match="protocol"):
            db.test_indices(4)


@pytest.mark.parametrize("name", ["small", "large"])
@pytest.mark.parametrize("n_nodes", [2, 4, 6])
def test_the_papers_test_goals(name, n_nodes):
    db = load_database(name)
    indices = db.test_indices(n_nodes)
    assert len(indices) == BOXES[name].expected_count  # their test files have N goals
    assert indices.min() >= 0 and indices.max() < len(db)
    goals = resolve_goals(f"{name}-test", n_nodes)
    np.testing.assert_array_equal(goals, db.goals(n_nodes)[indices])
    np.testing.assert_array_equal(goals, db.test_goals(n_nodes))
    # They come mostly from the sweep's first, uncompressed level (FACTS.md): far more often
    # than a uniform draw from the whole sweep would.
    uniform_share = 1 / (BOXES[name].divisions[2] + 1)
    assert np.mean(sweep_levels(BOXES[name])[indices] == 0) > 2 * uniform_share


def test_goal_sources(tmp_path):
    np.testing.assert_array_equal(resolve_goals("small", 4), load_database("small").goals(4))
    array = np.full((3, 2, 3), 0.5)
    np.testing.assert_array_equal(resolve_goals(array, 2), array)
    np.save(tmp_path / "goals.npy", array)
    np.testing.assert_array_equal(resolve_goals(tmp_path / "goals.npy", 2), array)
    np.savez(tmp_path / "goals.npz", goals=array)
    np.testing.assert_array_equal(resolve_goals(tmp_path / "goals.npz", 2), array)
    with pytest.raises(ValueError, match="shape"):
        resolve_goals(array, 4)
    truncated = tmp_path / "truncated.npy"
    truncated.write_bytes((tmp_path / "goals.npy").read_bytes()[:100])
    with pytest.raises(ValueError, match="not a readable"):
        resolve_goals(truncated, 2)
    with pytest.raises(ValueError, match="unknown database"):
        resolve_goals("medium-test", 2)


def test_load_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown database"):
        load_database("medium")
    with pytest.raises(FileNotFoundError):
        load_database(tmp_path / "missing.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"not a zip file")
    with pytest.raises(ValueError, match="not a readable"):
        load_database(corrupt)
    no_nodes = tmp_path / "no_nodes.npz"
    np.savez(no_nodes, tip=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="no 'nodes'"):
        load_database(no_nodes)
    wrong = save_database(tmp_path / "wrong.npz", np.zeros((2, 3)), np.zeros((2, 100, 3)))
    with pytest.raises(ValueError, match="malformed"):
        load_database(wrong)
    partial = save_database(tmp_path / "partial.npz", np.zeros((2, 3)), np.zeros((2, 200, 3)),
                            protocol=np.array(AUTHORS_SWEEP), box=np.array("small"))
    with pytest.raises(ValueError, match="not the 930"):
        load_database(partial).test_indices(4)
