"""Grading: lesson 9, training on the rod (reference: dlo_course.trainer.run_episode).

The library's run_episode is run with an "agent" whose act() is the test's policy and whose
update() records the batches it is given, on environments much faster than the rod.
"""

import math
from types import SimpleNamespace

import gymnasium
import numpy as np
import pytest

from dlo_course.config import DDPGConfig, TrainConfig
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


def library_episode(make_env, max_steps, seed, batch_size, updates_per_step, warmup):
    """The library's episode and the rewards of the batches its updates were given."""
    env = make_env()
    buffer = ReplayBuffer(env.observation_space.shape[0], env.action_space.shape[0], 500, seed=0)
    policy = policy_for(env, seed)
    batches = []
    agent = SimpleNamespace(act=lambda obs, noise: policy(obs),
                            update=lambda batch, reducer: batches.append(batch["rew"].copy())
                            or {})
    noise = SimpleNamespace(reset=lambda: None)
    # The exercise's episode ends at the goal: the library's with stop_at_goal=True.
    config = TrainConfig(env_id="unused", env_kwargs={}, steps_per_episode=max_steps,
                         warmup=warmup, stop_at_goal=True, updates_per_step=updates_per_step,
                         ddpg=DDPGConfig(batch_size=batch_size))
    result = run_episode(env, agent, buffer, noise, config, seed, None)
    return result, buffer, batches


# (environment, max_steps, batch_size, updates_per_step, warmup): the warm-up reached at
# the episode's last step, before it, at its first step, never; one and three updates per
# action; an explicit warm-up above and below a batch
CASES = [(lambda: ReachAt(3), 10, 3, 1, None), (lambda: ReachAt(3), 2, 1, 3, None),
         (lambda: ReachAt(50, limit=4), 10, 2, 2, 3),
         (lambda: gymnasium.make("Pendulum-v1"), 12, 4, 2, None),
         (lambda: gymnasium.make("Pendulum-v1"), 12, 8, 1, 2),
         (lambda: ReachAt(50, limit=5), 10, 64, 1, None)]
KEYS = ("reward", "length", "distance", "success", "updates")


def probe_play_episode(fn):
    out = []
    for k, (make_env, max_steps, batch_size, updates_per_step, warmup) in enumerate(CASES):
        env = make_env()
        buffer = ReplayBuffer(env.observation_space.shape[0], env.action_space.shape[0], 500,
                              seed=0)
        batches = []
        got = fn(env, policy_for(env, k), buffer, max_steps, k,
                 update=lambda batch: batches.append(np.array(batch["rew"])),
                 batch_size=batch_size, updates_per_step=updates_per_step, warmup=warmup)
        out.append({"stored": len(buffer),
                    "fields": {name: np.asarray(getattr(buffer, name)) for name in FIELDS},
                    "result": {key: float(got[key]) for key in KEYS if key in got},
                    "batches": batches})
    return out


@pytest.mark.exercise("play_episode", points=3, reference="dlo_course.trainer.run_episode")
def test_play_episode(student):
    got = student.run(probe_play_episode)
    for k, (case, mine) in enumerate(zip(CASES, got, strict=True)):
        make_env, max_steps, batch_size, updates_per_step, warmup = case
        expected, ref_buffer, ref_batches = library_episode(make_env, max_steps, k, batch_size,
                                                            updates_per_step, warmup)
        where = (f"case {k} (batch {batch_size}, {updates_per_step} update(s) per step, "
                 f"warmup {warmup})")
        assert mine["stored"] == len(ref_buffer), \
            f"{where}: {mine['stored']} transitions stored, expected {len(ref_buffer)}"
        for name in FIELDS:
            np.testing.assert_allclose(mine["fields"][name], getattr(ref_buffer, name),
                                       rtol=1e-6, err_msg=f"{where}: stored {name}")
        for key in KEYS:
            assert key in mine["result"], f"missing {key!r}"
            value = mine["result"][key]
            if math.isnan(expected[key]):
                assert math.isnan(value), f"{where}: {key} should be NaN"
            else:
                assert value == pytest.approx(expected[key], rel=1e-6), f"{where}: {key}"
        assert len(mine["batches"]) == len(ref_batches), (
            f"{where}: update called {len(mine['batches'])} times, expected "
            f"{len(ref_batches)}: after storing each transition, once the buffer holds "
            f"warmup (default: batch_size) transitions, updates_per_step updates")
        for i, (batch, ref) in enumerate(zip(mine["batches"], ref_batches)):
            np.testing.assert_allclose(batch, ref, rtol=1e-6, err_msg=(
                f"{where}: batch {i} differs: each update gets buffer.sample(batch_size), "
                f"drawn after the transition is stored"))


@pytest.mark.exercise("prediction_updates", points=1)
def test_prediction_updates(written_answer):
    written_answer.check()
