"""dlo_course.task: the task's numbers, defined once, and the observation layout (NumPy and
torch alike), checked against the environment's own observation."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from dlo_course.cli import NODES, main
from dlo_course.mesh import SELECTED_RINGS
from dlo_course.task import (DEFAULT_N_NODES, NODE_COUNTS, TABLE_THRESHOLDS, TRAIN_THRESHOLD,
                             ObservationLayout, nodes_of_observation_size, observation_size,
                             reached, split_observation)


def test_the_numbers():
    assert NODE_COUNTS == tuple(SELECTED_RINGS) == (2, 4, 6)
    assert DEFAULT_N_NODES in NODE_COUNTS
    assert TABLE_THRESHOLDS == (0.05, 0.03) and TRAIN_THRESHOLD == 0.05
    assert [observation_size(n) for n in NODE_COUNTS] == [18, 30, 42]
    assert [nodes_of_observation_size(s) for s in (18, 30, 42, 24, 3)] == [2, 4, 6, None, None]


def test_reached_is_strictly_below():
    assert reached(0.049, 0.05) and not reached(0.05, 0.05)
    np.testing.assert_array_equal(reached(np.array([0.01, 0.05, 0.2]), 0.05), [True, False, False])


@pytest.mark.parametrize("n_nodes", NODE_COUNTS)
def test_split_observation_numpy_and_torch(n_nodes):
    size = observation_size(n_nodes)
    obs = np.arange(2 * size, dtype=np.float32).reshape(2, size)
    parts = split_observation(obs, n_nodes)
    assert parts.tip.shape == parts.tip_velocity.shape == (2, 3)
    assert parts.current.shape == parts.desired.shape == (2, n_nodes, 3)
    np.testing.assert_array_equal(parts.tip_velocity[1], obs[1, 3:6])
    np.testing.assert_array_equal(parts.current[1].ravel(), obs[1, 6:6 + 3 * n_nodes])
    np.testing.assert_array_equal(parts.desired[1].ravel(), obs[1, 6 + 3 * n_nodes:])
    parts.desired[0] = -1.0  # views: writes reach the observation
    assert (obs[0, ObservationLayout(n_nodes).desired] == -1.0).all()
    single = split_observation(torch.as_tensor(obs[1]), n_nodes)
    assert isinstance(single.current, torch.Tensor) and single.current.shape == (n_nodes, 3)
    np.testing.assert_array_equal(single.current.numpy(), parts.current[1])
    with pytest.raises(ValueError, match=f"has {size} components, got {size + 1}"):
        split_observation(np.zeros(size + 1), n_nodes)


def test_the_layout_is_the_environments(make_env, far_goals):
    env = make_env(n_nodes=4, goals=far_goals)
    obs, _ = env.reset(seed=0)
    parts = split_observation(obs, 4)
    np.testing.assert_allclose(parts.tip, env.scene.tip_position(), atol=1e-6)
    np.testing.assert_allclose(parts.desired, env.goal, atol=1e-6)
    np.testing.assert_allclose(parts.current, env.scene.node_positions()[env.node_ids], atol=1e-6)
    assert env.observation_space.shape == (observation_size(4),)


def test_every_command_takes_node_counts_alike():
    assert [NODES.convert(v, None, None) for v in ("2", 4, " 6".strip())] == [2, 4, 6]
    runner = CliRunner()
    for command in ("train", "evaluate", "demo"):
        result = runner.invoke(main, [command, "--nodes", "3"])
        assert result.exit_code == 2 and "'3' is not one of '2', '4', '6'" in result.output, \
            (command, result.output)
