"""Hindsight relabelling (dlo_course.her): pure-NumPy checks, then one short rod episode."""

import gymnasium
import numpy as np
import pytest

from dlo_course.env import DLOShapeEnv, mean_node_distance
from dlo_course.her import (HindsightRelabeller, future_goal_steps, goal_distance, goal_layout,
                            relabel, split_goal_obs)


def fake_episode(rng, T=5, n_nodes=2, act_dim=3):
    """An episode with the rod's layout [tip 3 | velocity 3 | P_c 3m | P_d 3m]: P_c moves,
    P_d is one goal for the whole episode, next_obs[t] == obs[t + 1]."""
    goal = rng.normal(size=3 * n_nodes)
    states = [np.concatenate([rng.normal(size=6 + 3 * n_nodes), goal]) for _ in range(T + 1)]
    states = np.array(states, dtype=np.float32)
    return states[:-1], rng.uniform(-1, 1, (T, act_dim)).astype(np.float32), states[1:]


def test_layout_and_distance_are_the_environments():
    obs = np.arange(2 * 18, dtype=np.float32).reshape(2, 18)
    achieved, desired = split_goal_obs(obs, 2)
    assert achieved.shape == desired.shape == (2, 2, 3)
    np.testing.assert_array_equal(achieved[1].ravel(), obs[1, 6:12])
    np.testing.assert_array_equal(desired[1].ravel(), obs[1, 12:18])
    with pytest.raises(ValueError, match="an observation of 4 nodes has 30 components"):
        split_goal_obs(obs, 4)
    # The same arithmetic as the environment's reward, bit for bit.
    rng = np.random.default_rng(0)
    for m in (2, 4, 6):
        current, desired = rng.normal(size=(10, m, 3)), rng.normal(size=(10, m, 3))
        batch = goal_distance(current, desired)
        assert batch.shape == (10,)
        assert list(batch) == [mean_node_distance(c, d) for c, d in zip(current, desired)]


def test_future_goal_steps_come_from_the_same_episode_later():
    rng = np.random.default_rng(0)
    steps, goal_steps = future_goal_steps(6, 300, rng)
    assert steps.shape == goal_steps.shape == (6 * 300,)
    np.testing.assert_array_equal(np.bincount(steps), [300] * 6)
    assert np.all(goal_steps >= steps) and np.all(goal_steps < 6)
    for t in range(6):  # every later step is drawn, no earlier one
        assert set(goal_steps[steps == t]) == set(range(t, 6))
    again = future_goal_steps(6, 300, np.random.default_rng(0))[1]
    np.testing.assert_array_equal(goal_steps, again)  # seeded


def test_relabel_substitutes_the_goal_and_recomputes_reward_and_done():
    rng = np.random.default_rng(1)
    obs, act, next_obs = fake_episode(rng, T=5, n_nodes=2)
    originals = [a.copy() for a in (obs, act, next_obs)]
    steps, goal_steps = np.array([0, 0, 1, 3, 4]), np.array([0, 4, 2, 3, 4])
    threshold = 1.0
    out = relabel(obs, act, next_obs, steps, goal_steps, n_nodes=2, threshold=threshold)
    assert {k: v.shape for k, v in out.items()} == {
        "obs": (5, 18), "act": (5, 3), "rew": (5,), "next_obs": (5, 18), "done": (5,)}
    assert all(v.dtype == np.float32 for v in out.values())
    for i, (t, t_goal) in enumerate(zip(steps, goal_steps)):
        goal = next_obs[t_goal, 6:12]  # the P_c the rod reached at step t'
        np.testing.assert_array_equal(out["obs"][i], np.concatenate([obs[t, :12], goal]))
        np.testing.assert_array_equal(out["next_obs"][i],
                                      np.concatenate([next_obs[t, :12], goal]))
        np.testing.assert_array_equal(out["act"][i], act[t])
        distance = mean_node_distance(next_obs[t, 6:12].reshape(2, 3).astype(np.float64),
                                      goal.reshape(2, 3).astype(np.float64))
        assert out["rew"][i] == np.float32(-distance)
        assert out["done"][i] == float(distance < threshold)
    assert out["rew"][0] == 0 and out["done"][0] == 1  # t' = t: reached by this very action
    assert 0 in out["done"]  # and the threshold does cut
    for a, b in zip(originals, (obs, act, next_obs)):
        np.testing.assert_array_equal(a, b)  # the episode itself is left untouched

    with pytest.raises(ValueError, match="at or after"):
        relabel(obs, act, next_obs, np.array([2]), np.array([1]), 2, threshold)
    with pytest.raises(ValueError, match="at or after"):
        relabel(obs, act, next_obs, np.array([2]), np.array([5]), 2, threshold)


def test_relabeller_is_seeded_resumable_and_checks_the_reward():
    rng = np.random.default_rng(2)
    obs, act, next_obs = fake_episode(rng, T=4, n_nodes=2)
    achieved, desired = split_goal_obs(next_obs, 2)
    rew = -goal_distance(achieved, desired)
    her = HindsightRelabeller(n_nodes=2, threshold=0.05, k=3, seed=11)
    first = her.episode_copies(obs, act, rew, next_obs)
    assert len(first["rew"]) == 4 * 3
    state = her.state_dict()
    second = her.episode_copies(obs, act, rew, next_obs)
    resumed = HindsightRelabeller(n_nodes=2, threshold=0.05, k=3, seed=999)
    resumed.load_state_dict(state)
    again = resumed.episode_copies(obs, act, rew, next_obs)
    for key in first:
        np.testing.assert_array_equal(second[key], again[key])
    with pytest.raises(ValueError, match="reward differs"):
        her.episode_copies(obs, act, rew + 0.1, next_obs)
    with pytest.raises(ValueError, match="k must be"):
        HindsightRelabeller(2, 0.05, k=0)


def test_environments_without_the_goal_layout_are_refused():
    env = gymnasium.make("Pendulum-v1")
    with pytest.raises(ValueError, match="needs a goal-reaching environment"):
        goal_layout(env)
    env.close()


# --- one short episode on the rod (runs the real simulator: a handful of actions) ---

@pytest.mark.slow
def test_relabelled_rewards_are_the_rods_rewards_for_the_substituted_goal():
    """Play 3 actions, then replay them in an environment whose goals are the shapes the rod
    reached: its rewards and terminations are the relabelled ones."""
    actions = [[-1.0, 1.0, -0.5], [0.5, 1.0, -1.0], [1.0, -0.5, 0.0]]
    far_goal = np.array([[[1.0, 0.3, 0.7], [1.0, 0.3, 1.2]]])
    env = DLOShapeEnv(n_nodes=2, goals=far_goal)
    try:
        assert goal_layout(env) == (2, 0.05)
        obs, _ = env.reset(seed=0)
        episode = []
        for a in actions:
            next_obs, rew, *_ = env.step(a)
            episode.append((obs, np.float32(a), rew, next_obs))
            obs = next_obs
    finally:
        env.close()
    obs, act, rew, next_obs = (np.array(column) for column in zip(*episode))
    reached = split_goal_obs(next_obs, 2)[0]  # (3, 2, 3): P_c after each action

    # Every pair t <= t', with a threshold between the distances so both outcomes occur.
    steps, goal_steps = np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2])
    apart = goal_distance(reached[steps], reached[goal_steps])[steps != goal_steps]
    assert apart.min() < apart.max()
    threshold = float((apart.min() + apart.max()) / 2)
    copies = relabel(obs, act, next_obs, steps, goal_steps, 2, threshold)

    replay_env = DLOShapeEnv(n_nodes=2, goals=reached, threshold=threshold)
    try:
        env_reward, env_done = np.zeros((3, 3)), np.zeros((3, 3))  # [goal step t', step t]
        for t_goal in range(3):
            replay_env.reset(seed=0, options={"goal_index": t_goal})  # rebuilt: same start
            for t, a in enumerate(actions):
                replay_obs, r, terminated, *_ = replay_env.step(a)
                np.testing.assert_array_equal(replay_obs[6:12], next_obs[t, 6:12])  # same rod
                env_reward[t_goal, t], env_done[t_goal, t] = r, terminated
    finally:
        replay_env.close()
    # Equal up to the float32 rounding of the positions in the observation.
    np.testing.assert_allclose(copies["rew"], env_reward[goal_steps, steps], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(copies["done"], env_done[goal_steps, steps])
    assert set(copies["done"]) == {0.0, 1.0}
    # The real transitions' rewards are recomputed the same way (the relabeller checks it).
    HindsightRelabeller(2, threshold, k=2, seed=0).episode_copies(obs, act, rew, next_obs)
