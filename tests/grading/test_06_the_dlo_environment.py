"""Grading: lesson 6, the DLO environment (reference: dlo_course.env, RodScene.tip_target,
Gymnasium's TimeLimit).

The library's own methods are run on stand-in objects, so no simulator is started; the
inputs are built here and sent to the sandbox as data.
"""

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.wrappers import TimeLimit

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
    scene.clip_to_workspace = lambda target: RodScene.clip_to_workspace(scene, target)
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


class StandInRod(gym.Env):
    """DLOShapeEnv.step itself on a stand-in scene (no simulator): each action leaves the
    selected nodes at a planned mean distance from the goal, or blows the simulation up."""

    observation_space = spaces.Box(-10.0, 10.0, (6 + 6 * 4,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)

    def __init__(self, threshold, reset_distance, plan, rng):
        self.plan, self.rng, self.unstable = iter(plan), rng, False
        self.rod = SimpleNamespace(
            threshold=threshold, node_ids=np.array(selected_nodes(4)), goal_index=0,
            goal=np.zeros((4, 3)), _broken=False, _last_distance=reset_distance,
            _last_obs=np.zeros(self.observation_space.shape, np.float32),
            observation_space=self.observation_space)
        self.rod.scene = SimpleNamespace(
            tip_target=lambda action: np.zeros(3), move_tip_to=lambda target: None,
            node_positions=lambda: np.zeros((200, 3)), tip_position=lambda: np.zeros(3),
            tip_state=lambda: (np.zeros(3), np.zeros(3)),
            is_unstable=lambda nodes: self.unstable)
        self.rod._observe = lambda nodes: DLOShapeEnv._observe(self.rod, nodes)
        self.rod._info = lambda distance, unstable: DLOShapeEnv._info(self.rod, distance, unstable)

    def reset(self, *, seed=None, options=None):
        return self.rod._last_obs.copy(), {}

    def step(self, action):
        distance, self.unstable = next(self.plan)
        # the goal `distance` away from the nodes (all at 0) along random axes: the
        # library's mean distance is then exactly `distance`
        signs = self.rng.choice([-1.0, 1.0], size=(4, 1))
        self.rod.goal = np.eye(3)[self.rng.integers(3, size=4)] * distance * signs
        return DLOShapeEnv.step(self.rod, action)


def library_step_outcome(distance, threshold, steps, max_episode_steps, unstable, last_distance,
                         rng):
    """The ``steps``-th action since the reset through DLOShapeEnv.step and Gymnasium's
    TimeLimit, as make_env builds them (no TimeLimit for no limit), the earlier actions
    ``last_distance`` from the goal. Returns the distance the library computed and the
    outcome."""
    earlier = steps - 1 if max_episode_steps is not None else 0  # only TimeLimit counts
    plan = [(last_distance, False)] * earlier + [(distance, unstable)]
    rod = StandInRod(threshold, last_distance, plan, rng)
    env = rod if max_episode_steps is None else TimeLimit(rod, max_episode_steps)
    env.reset()
    for _ in range(earlier):
        env.step(np.zeros(3))
    _, reward, terminated, truncated, info = env.step(np.zeros(3))
    return info["distance"], {"reward": float(reward), "terminated": bool(terminated),
                              "truncated": bool(truncated), "is_success": bool(info["is_success"])}


def step_outcome_cases(rng):
    """(distance, threshold, steps, max_episode_steps, unstable, last_distance): the edges
    (at the threshold, at the limit, a blow-up below the threshold or at the limit), then
    fresh random draws."""
    yield from [(0.049, 0.05, 1, 30, False, 0.2), (0.05, 0.05, 1, 30, False, 0.2),
                (0.2, 0.05, 29, 30, False, 0.2), (0.2, 0.05, 30, 30, False, 0.2),
                (0.01, 0.03, 300, 300, False, 0.1), (0.2, 0.05, 10_000, None, False, 0.3),
                (0.01, 0.05, 3, 30, True, 0.17), (0.3, 0.05, 30, 30, True, 0.04),
                (0.02, 0.05, 1, None, True, 0.25)]
    for _ in range(25):
        threshold = float(rng.choice([0.03, 0.05, rng.uniform(0.01, 0.1)]))
        limit = int(rng.integers(1, 40)) if rng.random() < 0.8 else None
        steps = int(rng.integers(1, 45)) if limit is None else int(rng.integers(1, limit + 1))
        yield (float(rng.uniform(0, 2 * threshold)), threshold, steps, limit,
               bool(rng.random() < 0.25), float(rng.uniform(0, 0.4)))


def probe_step_outcome(fn, cases):
    out = []
    for distance, threshold, steps, limit, unstable, last in cases:
        got = dict(fn(distance, threshold, steps, limit, unstable=unstable, last_distance=last))
        out.append({"reward": float(got["reward"]),
                    **{k: bool(got[k]) for k in ("terminated", "truncated", "is_success")}})
    return out


@pytest.mark.exercise("step_outcome", points=2,
                      reference=("dlo_course.env.DLOShapeEnv.step",
                                 "gymnasium.wrappers.TimeLimit.step"))
def test_step_outcome(student):
    rng = np.random.default_rng()  # fresh cases at every grading
    cases, expected = [], []
    for distance, threshold, steps, limit, unstable, last in step_outcome_cases(rng):
        computed, outcome = library_step_outcome(distance, threshold, steps, limit, unstable,
                                                 last, rng)
        # the student gets the distance the library computed (exactly the planned one)
        assert unstable or computed == distance
        cases.append((distance, threshold, steps, limit, unstable, last))
        expected.append(outcome)
    assert expected[1]["terminated"] is False and expected[6]["reward"] == -0.17
    got = student.run(probe_step_outcome, cases)
    for outcome, want, case in zip(got, expected, cases, strict=True):
        assert outcome["reward"] == pytest.approx(want["reward"], rel=1e-12, abs=1e-15), \
            f"reward of step_outcome{case}"
        for key in ("terminated", "truncated", "is_success"):
            assert outcome[key] == want[key], f"{key} of step_outcome{case}: {outcome[key]}"


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_nothing", points=1)
def test_prediction_nothing(written_answer):
    written_answer.check()
