"""Grading: lesson 6, the DLO environment (reference: dlo_course.env, RodScene.tip_target).

The library's own methods are run on stand-in objects, so no simulator is started; the
inputs are built here and sent to the sandbox as data.
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


def probe_split_observation(fn, cases):
    out = []
    for obs, n_nodes in cases:
        parts = fn(np.array(obs), n_nodes)
        out.append({str(k): np.asarray(v) for k, v in dict(parts).items()})
    return out


@pytest.mark.exercise("split_observation", points=2, reference="dlo_course.env.DLOShapeEnv._observe")
def test_split_observation(student):
    rng = np.random.default_rng(6)
    cases = [library_observation(rng, n_nodes) + (n_nodes,) for n_nodes in (2, 4, 6)]
    got = student.run(probe_split_observation, [(obs, n) for obs, _, _, n in cases])
    for parts, (_, _, expected, _) in zip(got, cases, strict=True):
        assert set(parts) >= set(expected), f"missing keys: {set(expected) - set(parts)}"
        for key, value in expected.items():
            part = parts[key]
            assert part.shape == value.shape, f"{key}: shape {part.shape}, expected {value.shape}"
            np.testing.assert_allclose(part, value, rtol=1e-6, atol=1e-6, err_msg=key)


def library_tip_target(tip, action, initial_tip, params):
    scene = SimpleNamespace(params=params, initial_tip=np.asarray(initial_tip),
                            tip_position=lambda: np.asarray(tip))
    scene.workspace = RodScene.workspace.fget(scene)
    return RodScene.tip_target(scene, np.asarray(action))


PARAMS = [{}, {"v_max": 0.5, "action_duration": 0.1, "workspace_low": (-0.05, -0.1, -0.2),
               "workspace_high": (0.05, 0.3, 0.1)}]


def tip_target_cases():
    rng = np.random.default_rng(66)
    initial = np.array([1.198, 0.0, 1.631])
    for k in range(len(PARAMS)):
        for _ in range(40):
            tip = initial + rng.uniform(-0.4, 0.4, size=3)
            action = rng.uniform(-1, 1, size=3)
            action[rng.random(3) < 0.2] = rng.choice([-1.0, 1.0])
            yield tip, action, initial, k


def probe_tip_target(fn, cases):
    return [np.asarray(fn(np.array(tip), np.array(action), np.array(initial),
                          SimParams(**PARAMS[k])), dtype=np.float64)
            for tip, action, initial, k in cases]


@pytest.mark.exercise("tip_target", points=2, reference="dlo_course.simulation.RodScene.tip_target")
def test_tip_target(student):
    cases = list(tip_target_cases())
    got = student.run(probe_tip_target, cases)
    for target, (tip, action, initial, k) in zip(got, cases, strict=True):
        expected = library_tip_target(tip, action, initial, SimParams(**PARAMS[k]))
        np.testing.assert_allclose(target, expected, rtol=0, atol=1e-12)


def probe_mean_node_distance(fn, cases):
    out = []
    for current, desired in cases:
        got = fn(np.array(current), np.array(desired))
        out.append({"ndim": int(np.ndim(got)), "value": float(np.asarray(got).ravel()[0])})
    return out


@pytest.mark.exercise("mean_node_distance", points=2, reference="dlo_course.env.mean_node_distance")
def test_mean_node_distance(student):
    rng = np.random.default_rng(7)
    cases = [tuple(rng.normal(size=(2, n_nodes, 3))) for n_nodes in (1, 2, 4, 6)]
    current = np.array([[0.0, 0, 0], [1, 0, 0]])
    cases.append((current, current[::-1]))  # node i is compared with goal i, not the nearest
    # and with an observation's float32 parts, as the environment computes its reward
    _, distance, parts = library_observation(rng, 4)
    cases.append((parts["current"], parts["desired"]))
    got = student.run(probe_mean_node_distance, cases)
    expected = [mean_node_distance(c, d) for c, d in cases[:-1]] + [distance]
    for result, want in zip(got, expected, strict=True):
        assert result["ndim"] == 0, "return one number"
        assert result["value"] == pytest.approx(want, rel=1e-9)
    assert got[-2]["value"] == pytest.approx(1.0)


# DLOShapeEnv.step: terminated = distance < threshold (strictly);
# truncated = max_episode_steps is not None and steps >= max_episode_steps.
FLAG_CASES = [((0.049, 0.05, 1, 30), (True, False)), ((0.05, 0.05, 1, 30), (False, False)),
              ((0.2, 0.05, 29, 30), (False, False)), ((0.2, 0.05, 30, 30), (False, True)),
              ((0.01, 0.03, 300, 300), (True, True)), ((0.2, 0.05, 10_000, None), (False, False))]


def probe_episode_flags(fn):
    return [tuple(bool(x) for x in fn(*args)) for args, _ in FLAG_CASES]


@pytest.mark.exercise("episode_flags", points=1, reference="dlo_course.env.DLOShapeEnv.step")
def test_episode_flags(student):
    got = student.run(probe_episode_flags)
    for (args, expected), flags in zip(FLAG_CASES, got, strict=True):
        assert flags == expected, f"episode_flags{args} = {flags}"
