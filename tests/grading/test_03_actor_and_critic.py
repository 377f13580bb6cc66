"""Grading: lesson 3, actor and critic (reference: dlo_course.ddpg.mlp, Actor, Critic)."""

import random

import numpy as np
import pytest
import torch
from torch import nn

from dlo_course.ddpg import Actor, Critic, mlp

pytestmark = pytest.mark.notebook("03_actor_and_critic")

MLP_CASES = [(30, (256, 256, 256), 3, 3e-3), (5, (16, 8), 1, 0.1), (4, (), 2, 1e-2)]


def set_weights(net, in_dim):
    """Give ``net`` fixed random weights (by shape, in order) and return its outputs on fixed
    inputs: two networks with the same layers compute the same function."""
    gen = torch.Generator().manual_seed(2)
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(torch.randn(p.shape, generator=gen) * 0.5)
        return net(torch.randn(64, in_dim, generator=gen) * 3)


def probe_build_mlp(fn):
    """Per case: the parameters as built, and the outputs with the set_weights weights."""
    out = []
    for in_dim, hidden, out_dim, final_init in MLP_CASES:
        torch.manual_seed(0)
        net = fn(in_dim, hidden, out_dim, final_init)
        params = [p.detach().clone() for p in net.parameters()]
        out.append({"module": isinstance(net, nn.Module), "params": params,
                    "outputs": set_weights(net, in_dim)})
    return out


@pytest.mark.exercise("build_mlp", points=2, reference="dlo_course.ddpg.mlp")
def test_build_mlp(student):
    check_build_mlp(student.run(probe_build_mlp))


def check_build_mlp(got):
    for (in_dim, hidden, out_dim, final_init), mine in zip(MLP_CASES, got, strict=True):
        assert mine["module"], "return an nn.Module (an nn.Sequential)"
        reference = mlp(in_dim, hidden, out_dim, final_init)
        ref_params = list(reference.parameters())
        assert [tuple(p.shape) for p in mine["params"]] == [tuple(p.shape) for p in ref_params], \
            "the layers (and their order) differ from Linear-ReLU ... Linear"
        weight, bias = mine["params"][-2], mine["params"][-1]
        for name, p in (("weight", weight), ("bias", bias)):
            assert p.abs().max().item() <= final_init + 1e-9, f"output {name} outside +-final_init"
        # uniform in +-final_init, not zero, not constant: with n >= 9 output parameters a
        # correct initialisation fails this with probability 0.1**n <= 1e-9
        pooled = torch.cat([weight.reshape(-1), bias.reshape(-1)])
        assert pooled.abs().max().item() >= final_init / 10 and pooled.unique().numel() > 1, \
            "the output layer is not initialised uniformly in [-final_init, final_init]"
        if hidden:  # hidden layers keep PyTorch's default, uniform in +-1/sqrt(fan-in)
            bound = 1 / np.sqrt(in_dim)
            assert 0.5 * bound < mine["params"][0].abs().max().item() <= bound + 1e-6, \
                "the hidden layers must keep PyTorch's default initialisation"
        # same weights -> same function: the activations sit in the right places
        torch.testing.assert_close(mine["outputs"], set_weights(reference, in_dim))


SQUASH_BOXES = [([-1.0] * 3, [1.0] * 3), ([-2.0], [2.0]), ([0.0, -5.0], [1.0, 3.0])]


def reference_squash_action(raw, low, high):
    act_dim = len(low)
    actor = Actor(act_dim, act_dim, np.array(low.tolist()), np.array(high.tolist()),
                  hidden_sizes=())
    actor.net = nn.Identity()  # the library's forward on the raw outputs themselves
    return actor(raw)


def probe_squash_action(fn):
    gen = torch.Generator().manual_seed(3)
    out = []
    for low, high in SQUASH_BOXES:
        raw = torch.randn(50, len(low), generator=gen) * 4
        out.append(torch.as_tensor(fn(raw.clone(), torch.tensor(low), torch.tensor(high))))
    return out


@pytest.mark.exercise("squash_action", points=2, reference="dlo_course.ddpg.Actor.forward")
def test_squash_action(student):
    got = student.run(probe_squash_action)
    want = probe_squash_action(reference_squash_action)
    for mine, ref in zip(got, want, strict=True):
        assert mine.shape == ref.shape
        torch.testing.assert_close(mine.float(), ref)


CRITIC_CASES = [(30, 3, (256, 256, 256), 3e-3), (3, 1, (32, 32), 0.5), (5, 2, (16,), 0.1)]


def probe_critic(cls, seed):
    """Per case: the critic as built (its parameters), then, with weights drawn from ``seed``
    (by shape, in order), its Q-values on fresh inputs and their gradient with respect to
    the action."""
    gen = torch.Generator().manual_seed(seed)
    out = []
    for obs_dim, act_dim, hidden, final_init in CRITIC_CASES:
        torch.manual_seed(seed % 1000)
        critic = cls(obs_dim, act_dim, hidden, final_init)
        built = [p.detach().clone() for p in critic.parameters()]
        with torch.no_grad():
            for p in critic.parameters():
                p.copy_(torch.randn(p.shape, generator=gen) * 0.5)
        obs = torch.randn(23, obs_dim, generator=gen) * 2
        act = (torch.rand(23, act_dim, generator=gen) * 2 - 1).requires_grad_(True)
        q = torch.as_tensor(critic(obs, act))
        grad = None
        if q.requires_grad:
            (grad,) = torch.autograd.grad(q.sum(), act, allow_unused=True)
        out.append({"module": isinstance(critic, nn.Module), "params": built,
                    "q": q.detach(), "grad": grad})
    return out


@pytest.mark.exercise("Critic", points=2, reference="dlo_course.ddpg.Critic")
def test_critic(student):
    """The student's critic against the library's: same layers, same last-layer
    initialisation, and, given the same weights, the same Q-values and the same gradient
    with respect to the action, on weights and inputs drawn at every grading."""
    seed = random.SystemRandom().randrange(2**31)
    got = student.run(probe_critic, seed)
    want = probe_critic(Critic, seed)
    for (obs_dim, act_dim, hidden, final_init), mine, ref in zip(CRITIC_CASES, got, want,
                                                                   strict=True):
        where = f"Critic({obs_dim}, {act_dim}, {hidden}, {final_init})"
        assert mine["module"], f"{where} must be an nn.Module"
        assert [tuple(p.shape) for p in mine["params"]] == \
            [tuple(p.shape) for p in ref["params"]], \
            f"{where}: the layers differ from the library's MLP on obs_dim + act_dim = " \
            f"{obs_dim + act_dim} inputs with one output: {[tuple(p.shape) for p in mine['params']]}"
        pooled = torch.cat([p.reshape(-1) for p in mine["params"][-2:]])
        assert pooled.abs().max().item() <= final_init + 1e-9 and pooled.unique().numel() > 1, \
            f"{where}: the output layer is not initialised uniformly in +-final_init"
        assert tuple(mine["q"].shape) == (23, 1), \
            f"{where}: Q-values of shape {tuple(mine['q'].shape)} for a batch of 23, expected (23, 1)"
        # float32 sums in another order (another correct layout) differ in the last bits of
        # the largest values: the tolerances scale with them
        torch.testing.assert_close(
            mine["q"], ref["q"], rtol=1e-4, atol=1e-5 * float(ref["q"].abs().max()) + 1e-6,
            msg=lambda m: f"{where}: with the library's weights, other Q-values (is the "
                          f"observation first in the concatenation?): {m}")
        assert mine["grad"] is not None, \
            f"{where}: no gradient of Q reaches the action; the actor learns through dQ/da"
        torch.testing.assert_close(mine["grad"], ref["grad"], rtol=1e-4,
                                   atol=1e-5 * float(ref["grad"].abs().max()) + 1e-6,
                                   msg=lambda m: f"{where}: dQ/da differs: {m}")


COUNT_CASES = [(18, 3, (256, 256, 256)), (30, 3, (256, 256, 256)), (42, 3, (256, 256, 256)),
               (3, 1, (64, 32)), (5, 2, ())]


def reference_parameter_counts(obs_dim, act_dim, hidden):
    actor, critic = Actor(obs_dim, act_dim, hidden_sizes=hidden), \
        Critic(obs_dim, act_dim, hidden_sizes=hidden)
    return tuple(sum(p.numel() for p in m.parameters()) for m in (actor, critic))


def probe_parameter_counts(fn):
    return [tuple(int(n) for n in fn(*case)) for case in COUNT_CASES]


@pytest.mark.exercise("parameter_counts", points=2)
def test_parameter_counts(student):
    got = student.run(probe_parameter_counts)
    want = probe_parameter_counts(reference_parameter_counts)
    for case, mine, ref in zip(COUNT_CASES, got, want, strict=True):
        assert mine == ref, f"{mine} for {case}, expected {ref}"


@pytest.mark.exercise("prediction_parameters", points=1)
def test_prediction_parameters(written_answer):
    written_answer.check()
