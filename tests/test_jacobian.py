"""The classical baseline (dlo_course.jacobian): its three pieces on a linear system whose
Jacobian is known, the controller on the real rod, and ``dlo-course evaluate --controller``."""

import json

import numpy as np
import pytest

from dlo_course.evaluation import Controller, evaluate_thresholds, play_episode
from dlo_course.jacobian import (JacobianController, broyden_update,
                                 damped_least_squares_step, jacobian_from_probes)


@pytest.fixture
def linear_system():
    """x = A u: 4 nodes (12 values) that move linearly with the tip (3 values)."""
    return np.random.default_rng(14).normal(size=(12, 3))


# ------------------------------------------------------------------ jacobian_from_probes
def test_probes_along_each_axis_recover_a_linear_system(linear_system):
    A = linear_system
    tip_moves = 0.02 * np.eye(3)
    J = jacobian_from_probes(tip_moves, tip_moves @ A.T)
    assert J.shape == (12, 3)
    np.testing.assert_allclose(J, A, rtol=1e-12, atol=1e-12)


def test_any_independent_probes_recover_it_and_more_probes_too(linear_system):
    A = linear_system
    rng = np.random.default_rng(1)
    for k in (3, 5):
        tip_moves = rng.normal(scale=0.02, size=(k, 3))
        np.testing.assert_allclose(jacobian_from_probes(tip_moves, tip_moves @ A.T), A,
                                   rtol=1e-9, atol=1e-9)


def test_probes_that_miss_an_axis_are_refused(linear_system):
    tip_moves = np.array([[0.02, 0, 0], [0, 0.02, 0], [0.01, 0.01, 0]])  # nothing along z
    with pytest.raises(ValueError, match="span"):
        jacobian_from_probes(tip_moves, tip_moves @ linear_system.T)


# ------------------------------------------------------------------ broyden_update
def test_broyden_keeps_a_right_jacobian(linear_system):
    A = linear_system
    du = np.array([0.01, -0.02, 0.005])
    np.testing.assert_allclose(broyden_update(A, du, A @ du), A, rtol=0, atol=1e-15)


def test_broyden_moves_a_wrong_jacobian_towards_the_truth_along_the_step(linear_system):
    A = linear_system
    J = A + np.random.default_rng(2).normal(scale=0.5, size=A.shape)
    du = np.array([0.01, -0.02, 0.005])
    J_new = broyden_update(J, du, A @ du)
    np.testing.assert_allclose(J_new @ du, A @ du, rtol=1e-10, atol=1e-14)  # secant condition
    assert np.linalg.norm(J_new - A) < np.linalg.norm(J - A)
    # only the direction of the step changed: any direction orthogonal to it is kept
    other = np.cross(du, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(J_new @ other, J @ other, rtol=1e-12, atol=1e-14)
    # a partial update goes part of the way
    half = broyden_update(J, du, A @ du, gain=0.5)
    np.testing.assert_allclose(half, (J + J_new) / 2, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(broyden_update(J, du * 1e-4, A @ du, min_move=1e-3), J)


def test_repeated_broyden_updates_along_every_axis_converge(linear_system):
    A = linear_system
    J = np.zeros_like(A)
    for du in 0.01 * np.eye(3):
        J = broyden_update(J, du, A @ du)
    np.testing.assert_allclose(J, A, rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------ damped_least_squares_step
def test_undamped_step_solves_the_least_squares_problem(linear_system):
    A = linear_system
    error = np.random.default_rng(3).normal(size=12)
    want, *_ = np.linalg.lstsq(A, error, rcond=None)
    du = damped_least_squares_step(A, error, 0.0)
    assert du.shape == (3,)
    np.testing.assert_allclose(du, want, rtol=1e-10, atol=1e-12)
    # a reachable goal is reached exactly
    target = np.array([0.01, 0.02, -0.03])
    np.testing.assert_allclose(damped_least_squares_step(A, A @ target, 0.0), target,
                               rtol=1e-10, atol=1e-12)


def test_damped_step_minimises_its_objective_and_shrinks_with_lambda(linear_system):
    A = linear_system
    error = np.random.default_rng(4).normal(size=12)
    lengths = []
    for damping in (0.0, 0.1, 1.0, 10.0):
        du = damped_least_squares_step(A, error, damping)
        lengths.append(np.linalg.norm(du))
        def objective(x, damping=damping):
            return np.sum((A @ x - error) ** 2) + damping ** 2 * np.sum(x ** 2)

        nearby = np.random.default_rng(len(lengths)).normal(scale=1e-3, size=(5, 3))
        assert all(objective(du) <= objective(du + d) for d in nearby)  # any other move costs more
    assert all(a > b for a, b in zip(lengths, lengths[1:]))
    with pytest.raises(ValueError):
        damped_least_squares_step(A, error, -1.0)


# ------------------------------------------------------------------ the controller
def test_controller_probes_then_steps_within_the_action_box():
    controller = JacobianController(n_nodes=2)
    assert isinstance(controller, Controller)
    rng = np.random.default_rng(5)
    A = rng.normal(size=(6, 3))
    tip, nodes, goal = np.array([1.2, 0.0, 1.6]), rng.normal(size=6), rng.normal(size=6)

    def observe():
        return np.concatenate([tip, np.zeros(3), nodes, goal]).astype(np.float32)

    controller.reset(observe())
    for k in range(6):
        action = controller.act(observe())
        assert action.shape == (3,) and action.dtype == np.float32
        assert np.all(np.abs(action) <= 1.0)
        if k < 3:  # one probe per axis
            assert np.count_nonzero(action) == 1 and action[k] != 0
        move = action.astype(np.float64) * controller.metres_per_action
        tip, nodes = tip + move, nodes + A @ move  # a rod that is exactly linear
    np.testing.assert_allclose(controller.jacobian, A, rtol=1e-4, atol=1e-5)
    controller.reset(observe())
    assert controller.jacobian is None


@pytest.mark.slow
def test_controller_reduces_the_distance_to_a_near_goal_on_the_rod(make_env):
    # The goal: where the 2 nodes were after the tip moved 3 cm along -x and +y and rested.
    from dlo_course.simulation import RodScene  # noqa: F401  (PyBullet)

    env = make_env(n_nodes=2, goals=np.zeros((1, 2, 3)))
    env.reset(options={"goal_index": 0})
    for _ in range(2):
        env.step(np.array([-0.25, 0.25, 0.0]))
    for _ in range(8):
        env.step(np.zeros(3))
    goal = env.scene.node_positions()[env.node_ids]
    env.close()

    env = make_env(n_nodes=2, goals=goal[None], threshold=0.001)
    controller = JacobianController(n_nodes=2)
    controller.bind(env)
    obs, info = env.reset(options={"goal_index": 0})
    start = info["distance"]
    done, steps, info = play_episode(controller, env, obs, max_steps=10)
    assert steps == 10
    assert info["distance"] < 0.75 * start  # measured: 0.0142 m -> 0.0067 m


def test_evaluate_thresholds_takes_a_controller():
    goals = np.array([[[1.22, 0.0, 1.26], [1.22, 0.0, 0.73]]])
    results = evaluate_thresholds(JacobianController(2), goals, (0.05,), episodes=1,
                                  max_steps=4, show_progress=False)
    summary, records = results[0.05]
    assert summary.episodes == 1 and records[0].steps <= 4
    with pytest.raises(ValueError, match="controller is for 2 nodes"):
        evaluate_thresholds(JacobianController(2), goals, (0.05,), episodes=1, n_nodes=4)


def test_cli_evaluates_the_controller(tmp_path):
    from click.testing import CliRunner

    from dlo_course.cli import main

    goal_file = tmp_path / "goals.npy"
    np.save(goal_file, np.array([[[1.22, 0.0, 1.26], [1.22, 0.0, 0.73]]]))
    out = tmp_path / "jacobian.json"
    result = CliRunner().invoke(main, [
        "evaluate", "--controller", "jacobian", "--nodes", "2", "--database", str(goal_file),
        "--episodes", "1", "--max-steps", "4", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "done" in result.output and "final distance" in result.output
    data = json.loads(out.read_text())
    assert data["summary"]["episodes"] == 1 and len(data["episodes"]) == 1

    both = CliRunner().invoke(main, ["evaluate", "--controller", "jacobian",
                                     "--agent", str(tmp_path), "--episodes", "1"])
    assert both.exit_code != 0 and "not both" in both.output
    neither = CliRunner().invoke(main, ["evaluate", "--episodes", "1"])
    assert neither.exit_code != 0 and "--agent" in neither.output


def test_cli_names_every_controller_of_the_library():
    from dlo_course.cli import CONTROLLER_NAMES
    from dlo_course.jacobian import CONTROLLERS

    assert list(CONTROLLER_NAMES.choices) == list(CONTROLLERS)


def test_reproduce_evaluates_the_controller_cells_like_the_agents(tmp_path):
    from dlo_course.reproduce import Cell, evaluate_controller_cells

    cells = [Cell("with", 2, "small", 0.05), Cell("with", 2, "small", 0.03)]
    rows = evaluate_controller_cells("jacobian", episodes=1, max_steps=2, seed=0, cells=cells,
                                     cache=tmp_path)
    assert [row["cell"] for row in rows] == cells
    assert all(row["episodes"] == 1 and row["run_cells"] == 2 for row in rows)
    assert len(list(tmp_path.glob("jacobian_test_with_n2_small_*.json"))) == 1  # one shared run
    again = evaluate_controller_cells("jacobian", episodes=1, max_steps=2, seed=0,
                                      cells=cells, cache=tmp_path)  # from the cache
    assert [r["done_percent"] for r in again] == [r["done_percent"] for r in rows]
    with pytest.raises(ValueError, match="controller must be one of"):
        evaluate_controller_cells("nope", episodes=1, max_steps=2, seed=0, cells=cells)


def test_reproduce_refuses_an_unknown_controller_before_evaluating(tmp_path):
    from dlo_course.reproduce import reproduce

    with pytest.raises(ValueError, match="controller must be one of"):
        reproduce(tmp_path, controller="nope")
