"""Grading: lesson 1, RL and the Bellman equation (reference: dlo_course.ddpg.bellman_target)."""

import numpy as np
import pytest
import torch

from dlo_course.ddpg import bellman_target

pytestmark = pytest.mark.notebook("01_rl_and_the_bellman_equation")


@pytest.mark.exercise("discounted_return", points=1)
def test_discounted_return(exercise):
    rng = np.random.default_rng(1)
    for gamma in (0.0, 0.5, 0.9, 0.99, 1.0):
        rewards = rng.normal(size=int(rng.integers(1, 60)))
        expected = sum(gamma**k * r for k, r in enumerate(rewards))
        assert float(exercise(list(rewards), gamma)) == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert float(exercise([], 0.99)) == 0.0
    assert float(exercise([-1.0, -1.0, -1.0], 0.5)) == pytest.approx(-1.75)


@pytest.mark.exercise("bellman_target", points=2)
def test_bellman_target(exercise):
    gen = torch.Generator().manual_seed(1)
    for gamma in (0.99, 0.9, 0.0, 1.0):
        reward = torch.randn(64, 1, generator=gen)
        next_q = torch.randn(64, 1, generator=gen) * 10
        done = (torch.rand(64, 1, generator=gen) < 0.3).float()
        inputs = [t.clone() for t in (reward, next_q, done)]
        got = torch.as_tensor(exercise(*inputs, gamma))
        assert got.shape == (64, 1), f"shape {tuple(got.shape)}, expected (64, 1)"
        torch.testing.assert_close(got, bellman_target(reward, next_q, done, gamma))
        for before, after in zip((reward, next_q, done), inputs):
            assert torch.equal(before, after), "the inputs must not be modified"
    # terminal transitions: the target is the reward alone
    got = torch.as_tensor(exercise(torch.ones(3, 1), torch.full((3, 1), 100.0),
                                   torch.ones(3, 1), 0.99))
    torch.testing.assert_close(got, torch.ones(3, 1))


def reference_sweep(q, next_state, reward, done, gamma):
    best_next = torch.as_tensor(q.max(axis=1)[next_state])
    return bellman_target(torch.as_tensor(reward), best_next, torch.as_tensor(done), gamma).numpy()


@pytest.mark.exercise("q_iteration_sweep", points=2)
def test_q_iteration_sweep(exercise):
    rng = np.random.default_rng(11)
    for n_states, n_actions, gamma in [(7, 2, 0.99), (10, 3, 0.9), (4, 5, 0.0)]:
        q = rng.normal(size=(n_states, n_actions))
        next_state = rng.integers(n_states, size=(n_states, n_actions))
        reward = rng.normal(size=(n_states, n_actions))
        done = (rng.random((n_states, n_actions)) < 0.3).astype(float)
        q_before = q.copy()
        got = np.asarray(exercise(q, next_state, reward, done, gamma), dtype=np.float64)
        assert got.shape == q.shape
        np.testing.assert_allclose(got, reference_sweep(q_before, next_state, reward, done, gamma),
                                   rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(q, q_before, err_msg="q must not be modified")
