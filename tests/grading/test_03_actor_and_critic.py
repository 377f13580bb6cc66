"""Grading: lesson 3, actor and critic (reference: dlo_course.ddpg.mlp, Actor, Critic)."""

import numpy as np
import pytest
import torch
from torch import nn

from dlo_course.ddpg import Actor, Critic, mlp

pytestmark = pytest.mark.notebook("03_actor_and_critic")


@pytest.mark.exercise("build_mlp", points=2)
def test_build_mlp(exercise):
    for in_dim, hidden, out_dim, final_init in [(30, (256, 256, 256), 3, 3e-3),
                                                (5, (16, 8), 1, 0.1), (4, (), 2, 1e-2)]:
        torch.manual_seed(0)
        net = exercise(in_dim, hidden, out_dim, final_init)
        assert isinstance(net, nn.Module)
        reference = mlp(in_dim, hidden, out_dim, final_init)
        got_params, ref_params = list(net.parameters()), list(reference.parameters())
        assert [tuple(p.shape) for p in got_params] == [tuple(p.shape) for p in ref_params], \
            "the layers (and their order) differ from Linear-ReLU ... Linear"
        weight, bias = got_params[-2], got_params[-1]
        for name, p in (("weight", weight), ("bias", bias)):
            assert p.abs().max().item() <= final_init + 1e-9, f"output {name} outside +-final_init"
            if p.numel() >= 3:
                assert p.std().item() > final_init / 10, f"output {name} is not uniform"
        if hidden:  # hidden layers keep PyTorch's default, uniform in +-1/sqrt(fan-in)
            bound = 1 / np.sqrt(in_dim)
            assert 0.5 * bound < got_params[0].abs().max().item() <= bound + 1e-6, \
                "the hidden layers must keep PyTorch's default initialisation"
        # same weights -> same function: the activations sit in the right places
        with torch.no_grad():
            for mine, ref in zip(got_params, ref_params):
                mine.copy_(ref)
            x = torch.randn(64, in_dim) * 3
            torch.testing.assert_close(net(x), reference(x))


@pytest.mark.exercise("squash_action", points=2)
def test_squash_action(exercise):
    gen = torch.Generator().manual_seed(3)
    for low, high in [([-1.0] * 3, [1.0] * 3), ([-2.0], [2.0]), ([0.0, -5.0], [1.0, 3.0])]:
        act_dim = len(low)
        actor = Actor(act_dim, act_dim, np.array(low), np.array(high), hidden_sizes=())
        actor.net = nn.Identity()  # the library's forward on the raw outputs themselves
        raw = torch.randn(50, act_dim, generator=gen) * 4
        got = torch.as_tensor(exercise(raw.clone(), torch.tensor(low), torch.tensor(high)))
        assert got.shape == raw.shape
        torch.testing.assert_close(got.float(), actor(raw))


@pytest.mark.exercise("critic_value", points=1)
def test_critic_value(exercise):
    torch.manual_seed(4)
    for obs_dim, act_dim in [(30, 3), (3, 1)]:
        critic = Critic(obs_dim, act_dim, hidden_sizes=(32, 32), final_init=0.5)
        obs, act = torch.randn(17, obs_dim), torch.randn(17, act_dim)
        got = exercise(critic.net, obs, act)
        assert tuple(got.shape) == (17, 1), f"shape {tuple(got.shape)}, expected (17, 1)"
        torch.testing.assert_close(got, critic(obs, act))


@pytest.mark.exercise("parameter_counts", points=2)
def test_parameter_counts(exercise):
    for obs_dim, act_dim, hidden in [(18, 3, (256, 256, 256)), (30, 3, (256, 256, 256)),
                                     (42, 3, (256, 256, 256)), (3, 1, (64, 32)), (5, 2, ())]:
        actor, critic = Actor(obs_dim, act_dim, hidden_sizes=hidden), \
            Critic(obs_dim, act_dim, hidden_sizes=hidden)
        expected = tuple(sum(p.numel() for p in m.parameters()) for m in (actor, critic))
        got = tuple(int(n) for n in exercise(obs_dim, act_dim, hidden))
        assert got == expected, f"{got} for {(obs_dim, act_dim, hidden)}, expected {expected}"
