"""Grading: lesson 4, DDPG (reference: dlo_course.ddpg, dlo_course.noise.OUNoise)."""

import copy

import numpy as np
import pytest
import torch

from dlo_course import ddpg
from dlo_course.noise import OUNoise

pytestmark = pytest.mark.notebook("04_ddpg")


def q_and_target(seed, batch=32):
    gen = torch.Generator().manual_seed(seed)
    q = (torch.randn(batch, 1, generator=gen) * 3).requires_grad_(True)
    return q, torch.randn(batch, 1, generator=gen)


@pytest.mark.exercise("critic_loss", points=2)
def test_critic_loss(exercise):
    for seed in range(3):
        q, target = q_and_target(seed)
        got = exercise(q, target.clone())
        assert torch.as_tensor(got).dim() == 0, "the loss must be a scalar tensor"
        (grad,) = torch.autograd.grad(got, q)
        q_ref = q.detach().clone().requires_grad_(True)
        expected = ddpg.critic_loss(q_ref, target)
        (grad_ref,) = torch.autograd.grad(expected, q_ref)
        torch.testing.assert_close(got.detach(), expected.detach())
        torch.testing.assert_close(grad, grad_ref)
    q, target = q_and_target(9)
    with pytest.raises(ValueError):
        exercise(q, target.reshape(-1))  # (B, 1) against (B,)
    with pytest.raises(ValueError):
        exercise(q.reshape(-1), target)


@pytest.mark.exercise("policy_loss", points=1)
def test_policy_loss(exercise):
    for seed in range(3):
        q, _ = q_and_target(seed, batch=17)
        got = exercise(q)
        assert torch.as_tensor(got).dim() == 0, "the loss must be a scalar tensor"
        (grad,) = torch.autograd.grad(got, q)
        q_ref = q.detach().clone().requires_grad_(True)
        expected = ddpg.policy_loss(q_ref)
        (grad_ref,) = torch.autograd.grad(expected, q_ref)
        torch.testing.assert_close(got.detach(), expected.detach())
        torch.testing.assert_close(grad, grad_ref)


def pair(seed):
    torch.manual_seed(seed)
    source = ddpg.Critic(5, 2, hidden_sizes=(16, 8), final_init=0.3)
    target = ddpg.Critic(5, 2, hidden_sizes=(16, 8), final_init=0.3)  # different weights
    return source, target


@pytest.mark.exercise("polyak_update", points=2)
def test_polyak_update(exercise):
    for tau, target_requires_grad in [(0.01, False), (0.3, True), (1.0, False)]:
        source, target = pair(int(tau * 100))
        target.requires_grad_(target_requires_grad)
        expected = copy.deepcopy(target)
        ddpg.polyak_update(expected, source, tau)
        source_before = copy.deepcopy(source.state_dict())
        tensors = [p for p in target.parameters()]
        result = exercise(target, source, tau)
        if result is not None and result is not target:
            raise AssertionError("update the target in place (and return nothing)")
        for mine, ref in zip(target.parameters(), expected.parameters()):
            torch.testing.assert_close(mine.detach(), ref.detach(), rtol=1e-6, atol=1e-7)
        assert all(a is b for a, b in zip(tensors, target.parameters())), \
            "the target's parameter tensors must be updated in place, not replaced"
        for name, value in source.state_dict().items():
            assert torch.equal(value, source_before[name]), "the source must not change"
        assert all(p.grad is None for p in source.parameters())


@pytest.mark.exercise("ou_step", points=2)
def test_ou_step(exercise):
    for seed, size, theta, sigma, mu, dt in [(0, 3, 0.15, 0.3, 0.0, 1.0),
                                             (1, 1, 0.5, 0.1, 0.2, 1.0),
                                             (2, 4, 0.15, 0.2, -0.1, 0.05)]:
        rng = np.random.default_rng(seed)
        noise = OUNoise(size, theta=theta, sigma=sigma, mu=mu, dt=dt, seed=seed)
        x = np.full(size, mu, dtype=np.float64)
        for _ in range(50):
            x = np.asarray(exercise(x, rng, theta=theta, sigma=sigma, mu=mu, dt=dt))
            noise.sample()
            assert x.shape == (size,)
            np.testing.assert_allclose(x, noise.state, rtol=1e-9, atol=1e-12)
