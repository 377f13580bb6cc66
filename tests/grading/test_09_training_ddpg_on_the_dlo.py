"""Grading: lesson 9, training on the rod (reference: dlo_course.trainer.run_episode).

The library's run_episode is run with updates switched off (a huge warm-up) and an "agent"
whose act() is the test's policy, on environments much faster than the rod.
"""

import math
from types import SimpleNamespace

import gymnasium
import numpy as np
import pytest

from dlo_course.config import TrainConfig
from dlo_course.replay_buffer import ReplayBuffer
from dlo_course.trainer import run_episode

pytestmark = pytest.mark.notebook("09_training_ddpg_on_the_dlo")

FIELDS = ("obs", "act", "rew", "next_obs", "done")


class ReachAt(gymnasium.Env):
    """1-D toy: terminates with success at step `at`, truncates at step `limit`."""

    observation_space = gymnasium.spaces.Box(-10.0, 10.0, (2,), np.float32)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32)

    def __init__(self, at=3, limit=None):
        self.at, self.limit = at, limit

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        obs = self.np_random.normal(size=2).astype(np.float32)
        return obs, {"distance": 1.0, "is_success": False}

    def step(self, action):
        self.t += 1
        done = self.t == self.at
        obs = np.array([self.t / 10, float(np.sum(action))], np.float32)
        info = {"distance": 0.1 / self.t, "is_success": done}
        truncated = self.limit is not None and self.t >= self.limit
        return obs, -0.1 / self.t + float(action[0]), done, truncated, info


def policy_for(env, seed):
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(env.action_space.low, env.action_space.high).astype(np.float32)


def library_episode(make_env, max_steps, seed):
    env = make_env()
    buffer = ReplayBuffer(env.observation_space.shape[0], env.action_space.shape[0], 500, seed=0)
    policy = policy_for(env, seed)
    agent = SimpleNamespace(act=lambda obs, noise: policy(obs))
    noise = SimpleNamespace(reset=lambda: None)
    # The exercise's episode ends at the goal: the library's with stop_at_goal=True.
    config = TrainConfig(env_id="unused", env_kwargs={}, steps_per_episode=max_steps,
                         warmup=10**9, stop_at_goal=True)
    result = run_episode(env, agent, buffer, noise, config, seed, None)
    return result, buffer


CASES = [(lambda: ReachAt(3), 10), (lambda: ReachAt(3), 2), (lambda: ReachAt(50, limit=4), 10),
         (lambda: gymnasium.make("Pendulum-v1"), 12)]
KEYS = ("reward", "length", "distance", "success")


def probe_play_episode(fn):
    out = []
    for k, (make_env, max_steps) in enumerate(CASES):
        env = make_env()
        buffer = ReplayBuffer(env.observation_space.shape[0], env.action_space.shape[0], 500,
                              seed=0)
        got = fn(env, policy_for(env, k), buffer, max_steps, k)
        out.append({"stored": len(buffer),
                    "fields": {name: np.asarray(getattr(buffer, name)) for name in FIELDS},
                    "result": {key: float(got[key]) for key in KEYS if key in got}})
    return out


@pytest.mark.exercise("play_episode", points=2, reference="dlo_course.trainer.run_episode")
def test_play_episode(student):
    got = student.run(probe_play_episode)
    for k, ((make_env, max_steps), mine) in enumerate(zip(CASES, got, strict=True)):
        expected, ref_buffer = library_episode(make_env, max_steps, seed=k)
        assert mine["stored"] == len(ref_buffer), \
            f"case {k}: {mine['stored']} transitions stored, expected {len(ref_buffer)}"
        for name in FIELDS:
            np.testing.assert_allclose(mine["fields"][name], getattr(ref_buffer, name),
                                       rtol=1e-6, err_msg=f"case {k}: stored {name}")
        for key in KEYS:
            assert key in mine["result"], f"missing {key!r}"
            value = mine["result"][key]
            if math.isnan(expected[key]):
                assert math.isnan(value), f"case {k}: {key} should be NaN"
            else:
                assert value == pytest.approx(expected[key], rel=1e-6), f"case {k}: {key}"


# trainer.run_episode: warmup = config.warmup or batch_size; min over ranks >= warmup
START_CASES = [(([130, 127, 200], 128, None), False), (([130, 128, 200], 128, None), True),
               (([5], 4, None), True), (([10, 12], 128, 10), True), (([9, 12], 128, 10), False),
               (([0, 0], 1, None), False)]


def probe_updates_can_start(fn):
    return [bool(fn(*args)) for args, _ in START_CASES]


@pytest.mark.exercise("updates_can_start", points=1, reference="dlo_course.trainer.run_episode")
def test_updates_can_start(student):
    got = student.run(probe_updates_can_start)
    for (args, expected), value in zip(START_CASES, got, strict=True):
        assert value == expected, f"updates_can_start{args}"
