"""Grading: lesson 6, the DLO environment (reference: dlo_course.env, RodScene.tip_target).

The library's own methods are run on stand-in objects, so no simulator is started.
"""

from types import SimpleNamespace

import numpy as np
import pytest
from gymnasium import spaces

from dlo_course.env import DLOShapeEnv, mean_node_distance
from dlo_course.mesh import selected_nodes
from dlo_course.simulation import RodScene, SimParams, StepTimings

pytestmark = pytest.mark.notebook("06_the_dlo_environment")


def library_observation(rng, n_nodes):
    """An observation built by DLOShapeEnv._observe from random nodes, tip and goal."""
    nodes = rng.normal([1.2, 0.0, 0.8], 0.3, size=(200, 3))
    tip, velocity = rng.normal(size=3), rng.normal(size=3)
    goal = rng.normal([1.2, 0.0, 0.8], 0.3, size=(n_nodes, 3))
    bound = np.full(6 + 6 * n_nodes, 10.0, dtype=np.float32)
    bound[3:6] = 100.0
    fake_env = SimpleNamespace(
        scene=SimpleNamespace(tip_state=lambda: (tip, velocity), timings=StepTimings()),
        node_ids=np.array(selected_nodes(n_nodes)), goal=goal,
        observation_space=spaces.Box(-bound, bound, dtype=np.float32))
    obs, distance = DLOShapeEnv._observe(fake_env, nodes)
    return obs, distance, {"tip": tip, "tip_velocity": velocity,
                           "current": nodes[list(selected_nodes(n_nodes))], "desired": goal}


@pytest.mark.exercise("split_observation", points=2)
def test_split_observation(exercise):
    rng = np.random.default_rng(6)
    for n_nodes in (2, 4, 6):
        obs, _, expected = library_observation(rng, n_nodes)
        got = exercise(obs.copy(), n_nodes)
        assert set(got) >= set(expected), f"missing keys: {set(expected) - set(got)}"
        for key, value in expected.items():
            part = np.asarray(got[key])
            assert part.shape == value.shape, f"{key}: shape {part.shape}, expected {value.shape}"
            np.testing.assert_allclose(part, value, rtol=1e-6, atol=1e-6, err_msg=key)


def library_tip_target(tip, action, initial_tip, params):
    scene = SimpleNamespace(params=params, initial_tip=np.asarray(initial_tip),
                            tip_position=lambda: np.asarray(tip))
    scene.workspace = RodScene.workspace.fget(scene)
    return RodScene.tip_target(scene, np.asarray(action))


@pytest.mark.exercise("tip_target", points=2)
def test_tip_target(exercise):
    rng = np.random.default_rng(66)
    initial = np.array([1.198, 0.0, 1.631])
    other = SimParams(v_max=0.5, action_duration=0.1, workspace_low=(-0.05, -0.1, -0.2),
                      workspace_high=(0.05, 0.3, 0.1))
    for params in (SimParams(), other):
        for _ in range(40):
            tip = initial + rng.uniform(-0.4, 0.4, size=3)
            action = rng.uniform(-1, 1, size=3)
            action[rng.random(3) < 0.2] = rng.choice([-1.0, 1.0])
            got = np.asarray(exercise(tip.copy(), action.copy(), initial.copy(), params))
            np.testing.assert_allclose(got, library_tip_target(tip, action, initial, params),
                                       rtol=0, atol=1e-12)


@pytest.mark.exercise("mean_node_distance", points=2)
def test_mean_node_distance(exercise):
    rng = np.random.default_rng(7)
    for n_nodes in (1, 2, 4, 6):
        current, desired = rng.normal(size=(2, n_nodes, 3))
        got = exercise(current.copy(), desired.copy())
        assert np.ndim(got) == 0, "return one number"
        assert float(got) == pytest.approx(mean_node_distance(current, desired), rel=1e-9)
    # node i is compared with goal i, not with the nearest goal
    current = np.array([[0.0, 0, 0], [1, 0, 0]])
    assert float(exercise(current, current[::-1])) == pytest.approx(1.0)
    # and with an observation's float32 parts, as the environment computes its reward
    obs, distance, parts = library_observation(rng, 4)
    assert float(exercise(parts["current"], parts["desired"])) == pytest.approx(distance)


@pytest.mark.exercise("episode_flags", points=1)
def test_episode_flags(exercise):
    # DLOShapeEnv.step: terminated = distance < threshold (strictly);
    # truncated = max_episode_steps is not None and steps >= max_episode_steps.
    cases = [((0.049, 0.05, 1, 30), (True, False)), ((0.05, 0.05, 1, 30), (False, False)),
             ((0.2, 0.05, 29, 30), (False, False)), ((0.2, 0.05, 30, 30), (False, True)),
             ((0.01, 0.03, 300, 300), (True, True)), ((0.2, 0.05, 10_000, None), (False, False))]
    for args, expected in cases:
        got = exercise(*args)
        assert tuple(bool(x) for x in got) == expected, f"episode_flags{args} = {got}"
