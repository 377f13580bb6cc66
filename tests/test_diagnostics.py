"""dlo_course.diagnostics: the measurements of lesson 15 (a saturated actor, the critic
against Monte-Carlo returns)."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from dlo_course import diagnostics
from dlo_course.config import DDPGConfig, TrainConfig
from dlo_course.ddpg import Actor, Critic
from dlo_course.replay_buffer import ReplayBuffer
from dlo_course.trainer import train


def test_saturation_report_by_hand():
    actor = Actor(2, 2, action_low=[-2, 0], action_high=[2, 1], hidden_sizes=(4,))
    u = np.array([[0.0, 10.0], [3.0, -0.5], [-2.0, 0.0], [-4.0, 1.0]])
    actor.preactivation = lambda obs: torch.as_tensor(u, dtype=torch.float32)
    report = diagnostics.saturation_report(actor, np.zeros((4, 2)), threshold=0.99)
    # |tanh| > 0.99 for |u| > 2.65: 10, 3, -4
    assert report["saturated"] == pytest.approx(3 / 8)
    np.testing.assert_allclose(report["saturated_per_dim"], [0.5, 0.25])
    assert report["preactivation_abs_mean"] == pytest.approx(np.abs(u).mean(), rel=1e-6)
    assert report["tanh_gradient"] == pytest.approx(np.mean(1 - np.tanh(u) ** 2), rel=1e-5)


def test_saturation_report_of_a_real_actor_follows_its_preactivation():
    torch.manual_seed(0)
    actor = Actor(3, 2, hidden_sizes=(8, 8), final_init=3.0)
    obs = np.random.default_rng(0).normal(size=(50, 3)) * 5
    report = diagnostics.saturation_report(actor, obs)
    with torch.no_grad():
        u = actor.preactivation(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    assert report["saturated"] == pytest.approx(np.mean(np.abs(np.tanh(u)) > 0.99))
    assert report["saturated_per_dim"].shape == (2,)
    assert 0 < report["tanh_gradient"] < 1


def test_bound_share():
    actions = np.array([[2.0, 0.0], [-1.9, 1.0], [0.5, 0.999], [-2.0, 0.5]])
    # normalised: x / 2 -> 1, -0.95, 0.25, -1 and (y - 0.5) / 0.5 -> -1, 1, 0.998, 0
    np.testing.assert_allclose(diagnostics.bound_share(actions, [-2, 0], [2, 1]), [0.5, 0.75])


def test_discounted_returns():
    np.testing.assert_allclose(diagnostics.discounted_returns([1.0, 2.0, 3.0], 0.5),
                               [1 + 0.5 * 2 + 0.25 * 3, 2 + 0.5 * 3, 3.0])
    np.testing.assert_allclose(diagnostics.discounted_returns([1.0, 1.0], 0.9, bootstrap=10.0),
                               [1 + 0.9 + 0.81 * 10, 1 + 9.0])
    assert diagnostics.discounted_returns([], 0.9).shape == (0,)
    rewards = np.random.default_rng(0).normal(size=20)
    g = diagnostics.discounted_returns(rewards, 0.99)
    assert g[0] == pytest.approx(sum(0.99 ** k * r for k, r in enumerate(rewards)))


def test_critic_check_and_record_episode():
    env = gym.make("Pendulum-v1", max_episode_steps=15)
    torch.manual_seed(0)
    actor, critic = Actor(3, 1, -2.0, 2.0, hidden_sizes=(8,)), Critic(3, 1, hidden_sizes=(8,))
    episode = diagnostics.record_episode(env, actor, seed=3)
    again = diagnostics.record_episode(env, actor, seed=3, max_steps=5)
    env.close()
    assert episode["obs"].shape == (15, 3) and episode["act"].shape == (15, 1)
    assert episode["rew"].shape == (15,) and not episode["terminated"]
    np.testing.assert_array_equal(again["rew"], episode["rew"][:5])
    returns = diagnostics.discounted_returns(episode["rew"], 0.99)
    check = diagnostics.critic_check(critic, episode["obs"], episode["act"], returns)
    with torch.no_grad():
        q = critic(torch.as_tensor(episode["obs"]), torch.as_tensor(episode["act"])).numpy()
    np.testing.assert_allclose(check["q"], q.ravel(), rtol=1e-6)
    assert check["correlation"] == pytest.approx(np.corrcoef(check["q"], returns)[0, 1])
    assert check["bias"] == pytest.approx(q.mean() - returns.mean(), rel=1e-5)
    perfect = diagnostics.critic_check(lambda o, a: torch.as_tensor(returns[:, None]),
                                       episode["obs"], episode["act"], returns)
    assert perfect["correlation"] == pytest.approx(1.0) and perfect["bias"] == pytest.approx(0)
    with pytest.raises(ValueError):
        diagnostics.critic_check(critic, episode["obs"], episode["act"], returns[:-1])


def test_read_progress_file_and_run_buffer(tmp_path):
    config = TrainConfig(env_id="Pendulum-v1", env_kwargs={}, episodes=2, steps_per_episode=10,
                         checkpoint_every=10**6, out_dir=str(tmp_path / "run"), seed=0,
                         ddpg=DDPGConfig(hidden_sizes=(8,), batch_size=4))
    run = train(config, progress=False)
    progress = diagnostics.read_progress_file(run / "progress.csv")
    np.testing.assert_array_equal(progress["episode"], [1, 2])
    buffer = diagnostics.run_buffer(run)
    assert buffer["obs"].shape == (20, 3) and buffer["act"].shape == (20, 1)
    assert np.all(np.abs(buffer["act"]) <= 2.0)
    # the rows are the transitions in the order they were played
    np.testing.assert_array_equal(buffer["next_obs"][:9], buffer["obs"][1:10])
    assert isinstance(ReplayBuffer(3, 1).state_dict()["obs"], np.ndarray)
