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


def probe_loss(fn, batch):
    """Value and gradient (w.r.t. q) of a loss of q (and a target) for three seeds."""
    out = []
    for seed in range(3):
        q, target = q_and_target(seed, batch)
        loss = fn(q, target.clone()) if batch == 32 else fn(q)
        loss = torch.as_tensor(loss)
        (grad,) = torch.autograd.grad(loss, q) if loss.requires_grad else (None,)
        out.append({"loss": loss.detach(), "grad": grad})
    return out


def check_loss(got, want):
    for mine, ref in zip(got, want, strict=True):
        assert mine["loss"].dim() == 0, "the loss must be a scalar tensor"
        torch.testing.assert_close(mine["loss"].double(), ref["loss"].double())
        assert mine["grad"] is not None, "the loss must be differentiable with respect to q"
        torch.testing.assert_close(mine["grad"], ref["grad"])


def probe_critic_loss(fn):
    return probe_loss(fn, 32)


def probe_critic_loss_shapes(fn):
    """The exception raised for (B, 1) against (B,) and (B,) against (B, 1), or None."""
    q, target = q_and_target(9)
    raised = []
    for args in [(q, target.reshape(-1)), (q.reshape(-1), target)]:
        try:
            fn(*args)
            raised.append(None)
        except Exception as err:  # noqa: BLE001
            raised.append(type(err).__name__)
    return raised


@pytest.mark.exercise("critic_loss", points=1.5, reference="dlo_course.ddpg.critic_loss")
def test_critic_loss(student):
    check_loss(student.run(probe_critic_loss), probe_critic_loss(ddpg.critic_loss))


@pytest.mark.exercise("critic_loss", points=0.5, reference="dlo_course.ddpg.critic_loss")
def test_critic_loss_refuses_mismatched_shapes(student):
    """The secondary requirement (the ValueError), worth points only with a right loss."""
    try:
        check_loss(student.run(probe_critic_loss), probe_critic_loss(ddpg.critic_loss))
    except AssertionError:
        pytest.fail("the loss itself is wrong: no points for the shape check", pytrace=False)
    raised = student.run(probe_critic_loss_shapes)
    assert raised == ["ValueError", "ValueError"], \
        f"shapes (B, 1) and (B,) must raise ValueError (raised: {raised}); broadcasting them " \
        f"would compare every Q with every target"


def probe_policy_loss(fn):
    return probe_loss(fn, 17)


@pytest.mark.exercise("policy_loss", points=1, reference="dlo_course.ddpg.policy_loss")
def test_policy_loss(student):
    check_loss(student.run(probe_policy_loss), probe_policy_loss(ddpg.policy_loss))


POLYAK_CASES = [(0.01, False), (0.3, True), (1.0, False)]  # (tau, target requires grad)


def pair(seed):
    torch.manual_seed(seed)
    source = ddpg.Critic(5, 2, hidden_sizes=(16, 8), final_init=0.3)
    target = ddpg.Critic(5, 2, hidden_sizes=(16, 8), final_init=0.3)  # different weights
    return source, target


def probe_polyak_update(fn):
    out = []
    for tau, target_requires_grad in POLYAK_CASES:
        source, target = pair(int(tau * 100))
        target.requires_grad_(target_requires_grad)
        source_before = copy.deepcopy(source.state_dict())
        tensors = list(target.parameters())
        result = fn(target, source, tau)
        out.append({
            "returns_nothing": result is None or result is target,
            "params": [p.detach().clone() for p in target.parameters()],
            "in_place": all(a is b for a, b in zip(tensors, target.parameters())),
            "source_kept": all(torch.equal(v, source_before[k])
                               for k, v in source.state_dict().items()),
            "source_grads_none": all(p.grad is None for p in source.parameters())})
    return out


@pytest.mark.exercise("polyak_update", points=2, reference="dlo_course.ddpg.polyak_update")
def test_polyak_update(student):
    got = student.run(probe_polyak_update)
    for (tau, _), mine in zip(POLYAK_CASES, got, strict=True):
        source, expected = pair(int(tau * 100))
        with torch.no_grad():
            ddpg.polyak_update(expected, source, tau)
        assert mine["returns_nothing"], "update the target in place (and return nothing)"
        ref = list(expected.parameters())
        assert len(mine["params"]) == len(ref)
        for p, r in zip(mine["params"], ref):
            torch.testing.assert_close(p, r.detach(), rtol=1e-6, atol=1e-7)
        assert mine["in_place"], "the target's parameter tensors must be updated in place, " \
                                 "not replaced"
        assert mine["source_kept"], "the source must not change"
        assert mine["source_grads_none"], "the update must not leave gradients on the source"


OU_CASES = [(0, 3, 0.15, 0.3, 0.0, 1.0), (1, 1, 0.5, 0.1, 0.2, 1.0), (2, 4, 0.15, 0.2, -0.1, 0.05)]


def probe_ou_step(fn):
    out = []
    for seed, size, theta, sigma, mu, dt in OU_CASES:
        rng = np.random.default_rng(seed)
        x = np.full(size, mu, dtype=np.float64)
        states = []
        for _ in range(50):
            x = np.asarray(fn(x, rng, theta=theta, sigma=sigma, mu=mu, dt=dt))
            states.append(x)
        out.append(states)
    return out


@pytest.mark.exercise("ou_step", points=2, reference="dlo_course.noise.OUNoise.sample")
def test_ou_step(student):
    got = student.run(probe_ou_step)
    for (seed, size, theta, sigma, mu, dt), states in zip(OU_CASES, got, strict=True):
        noise = OUNoise(size, theta=theta, sigma=sigma, mu=mu, dt=dt, seed=seed)
        for x in states:
            noise.sample()
            assert x.shape == (size,)
            np.testing.assert_allclose(x, noise.state, rtol=1e-9, atol=1e-12)
