import numpy as np
import pytest
import torch

from dlo_course.ddpg import (DDPG, Actor, Critic, DDPGConfig, bellman_target, critic_loss,
                             load_network, polyak_update, policy_loss, save_network)

SMALL = DDPGConfig(hidden_sizes=(16, 16), batch_size=8)


def random_batch(rng: np.random.Generator, b: int = 8, obs_dim: int = 5, act_dim: int = 2):
    return {"obs": rng.normal(size=(b, obs_dim)), "act": rng.uniform(-1, 1, (b, act_dim)),
            "rew": rng.normal(size=b), "next_obs": rng.normal(size=(b, obs_dim)),
            "done": (rng.random(b) < 0.3).astype(np.float32)}


def test_paper_defaults():
    c = DDPGConfig()
    assert (c.actor_lr, c.critic_lr, c.batch_size, c.buffer_size, c.gamma, c.tau) == \
        (1e-4, 1e-3, 128, 50_000, 0.99, 0.01)
    assert c.hidden_sizes == (256, 256, 256)
    assert (c.noise_theta, c.noise_sigma, c.noise_mu) == (0.15, 0.3, 0.0)


def test_bellman_target_by_hand():
    r = torch.tensor([[1.0], [2.0], [-0.5]])
    next_q = torch.tensor([[10.0], [20.0], [4.0]])
    d = torch.tensor([[0.0], [1.0], [0.0]])
    # 1 + 0.5 * 10;  terminal: only r;  -0.5 + 0.5 * 4
    torch.testing.assert_close(bellman_target(r, next_q, d, 0.5),
                               torch.tensor([[6.0], [2.0], [1.5]]))


def test_losses_by_hand():
    q = torch.tensor([[1.0], [3.0]])
    assert critic_loss(q, torch.tensor([[0.0], [1.0]])).item() == pytest.approx((1 + 4) / 2)
    assert policy_loss(q).item() == pytest.approx(-2.0)
    with pytest.raises(ValueError, match="same shape"):
        critic_loss(q, torch.tensor([0.0, 1.0]))  # (B,1) vs (B,) would broadcast to (B,B)


def test_polyak_update_by_hand():
    target, source = torch.nn.Linear(2, 1), torch.nn.Linear(2, 1)
    with torch.no_grad():
        target.weight.copy_(torch.tensor([[1.0, -2.0]]))
        target.bias.fill_(4.0)
        source.weight.copy_(torch.tensor([[5.0, 2.0]]))
        source.bias.fill_(0.0)
    polyak_update(target, source, tau=0.25)
    # 0.25 * W + 0.75 * W_T
    torch.testing.assert_close(target.weight, torch.tensor([[2.0, -1.0]]))
    torch.testing.assert_close(target.bias, torch.tensor([3.0]))
    torch.testing.assert_close(source.weight, torch.tensor([[5.0, 2.0]]))  # untouched


def test_network_shapes_and_actor_bounds():
    critic = Critic(5, 2, hidden_sizes=(16,))
    assert critic(torch.zeros(7, 5), torch.zeros(7, 2)).shape == (7, 1)
    low, high = np.array([-2.0, 0.0]), np.array([2.0, 1.0])
    actor = Actor(5, 2, low, high, hidden_sizes=(16,))
    a = actor(torch.randn(100, 5) * 100)
    assert a.shape == (100, 2)
    assert torch.all(a >= torch.tensor(low, dtype=torch.float32))
    assert torch.all(a <= torch.tensor(high, dtype=torch.float32))
    # a saturated tanh reaches the bounds exactly: scaling maps [-1, 1] onto [low, high]
    with torch.no_grad():
        actor.net[-1].bias.copy_(torch.tensor([100.0, -100.0]))
    torch.testing.assert_close(actor(torch.zeros(1, 5)), torch.tensor([[2.0, 0.0]]))


def test_act_clips_noisy_actions_to_the_bounds():
    class HugeNoise:
        def sample(self):
            return np.array([100.0, -100.0], dtype=np.float32)

    agent = DDPG(5, 2, action_low=[-2, -1], action_high=[2, 1], config=SMALL)
    a = agent.act(np.zeros(5, dtype=np.float32), HugeNoise())
    assert a.shape == (2,) and a.dtype == np.float32
    np.testing.assert_array_equal(a, [2.0, -1.0])
    assert agent.act(np.zeros((3, 5))).shape == (3, 2)


def test_targets_start_as_copies():
    agent = DDPG(5, 2, config=SMALL)
    for net, target in ((agent.actor, agent.actor_target), (agent.critic, agent.critic_target)):
        assert net is not target
        for p, pt in zip(net.parameters(), target.parameters()):
            assert torch.equal(p, pt) and p.data_ptr() != pt.data_ptr()
            assert not pt.requires_grad


def test_update_moves_networks_and_targets_by_tau():
    torch.manual_seed(0)
    agent = DDPG(5, 2, config=SMALL)
    before = {name: [p.detach().clone() for p in getattr(agent, name).parameters()]
              for name in ("actor", "critic", "actor_target", "critic_target")}
    calls = []
    stats = agent.update(random_batch(np.random.default_rng(0)),
                         grad_reducer=lambda module: calls.append(module))
    assert calls == [agent.critic, agent.actor]
    assert set(stats) == {"critic_loss", "policy_loss", "q_mean"}
    assert all(np.isfinite(v) for v in stats.values())
    tau = SMALL.tau
    for name in ("actor", "critic"):
        net, target = getattr(agent, name), getattr(agent, name + "_target")
        for p_old, p_new, t_old, t_new in zip(before[name], net.parameters(),
                                             before[name + "_target"], target.parameters()):
            assert not torch.equal(p_old, p_new), f"{name} did not change"
            torch.testing.assert_close(t_new, tau * p_new + (1 - tau) * t_old)
    assert all(p.requires_grad for p in agent.critic.parameters())  # unfrozen again


def test_state_round_trip_gives_identical_updates():
    torch.manual_seed(0)
    a = DDPG(5, 2, config=SMALL)
    a.update(random_batch(np.random.default_rng(1)))  # so Adam has moments to save
    b = DDPG(5, 2, config=SMALL)
    b.load_state_dict(a.state_dict())
    batch = random_batch(np.random.default_rng(2))
    assert a.update(batch) == b.update(batch)
    for name in ("actor", "critic", "actor_target", "critic_target"):
        for p, q in zip(getattr(a, name).parameters(), getattr(b, name).parameters()):
            assert torch.equal(p, q)


def test_save_and_load_network(tmp_path):
    actor = Actor(5, 2, -2.0, 2.0, hidden_sizes=(8,))
    save_network(actor, tmp_path / "actor.pt")
    loaded = load_network(tmp_path / "actor.pt")
    assert isinstance(loaded, Actor)
    x = torch.randn(4, 5)
    assert torch.equal(actor(x), loaded(x))


def test_bad_config():
    with pytest.raises(ValueError, match="tau"):
        DDPGConfig(tau=0.0)
    with pytest.raises(ValueError, match="bounds"):
        Actor(3, 1, action_low=-np.inf, action_high=np.inf)


# --- course options (off by default: the paper has neither) ---

def test_course_options_are_off_by_default():
    c = DDPGConfig()
    assert not c.normalize_obs and c.preactivation_l2 == 0.0
    agent = DDPG(5, 2, config=SMALL)
    obs = torch.randn(4, 5)
    torch.testing.assert_close(agent.actor.scaling(obs), obs)  # identity scaling


def test_observation_scaling_is_applied_and_saved(tmp_path):
    offset, scale = np.arange(5.0), np.array([1.0, 2.0, 4.0, 0.5, 10.0])
    cfg = DDPGConfig(hidden_sizes=(16, 16), batch_size=8, normalize_obs=True)
    agent = DDPG(5, 2, config=cfg, obs_offset=offset, obs_scale=scale)
    obs = torch.randn(3, 5, dtype=torch.float32)
    expected_input = (obs - torch.tensor(offset, dtype=torch.float32)) / torch.tensor(
        scale, dtype=torch.float32)
    torch.testing.assert_close(agent.actor.preactivation(obs), agent.actor.net(expected_input))
    act = torch.rand(3, 2)
    torch.testing.assert_close(agent.critic(obs, act),
                               agent.critic.net(torch.cat([expected_input, act], dim=-1)))
    # The scaling travels with the saved network, so evaluation needs no extra file.
    save_network(agent.actor, tmp_path / "actor.pt")
    loaded = load_network(tmp_path / "actor.pt")
    torch.testing.assert_close(loaded(obs), agent.actor(obs))
    # The scaling is never trained.
    assert all(p.shape != (5,) for p in agent.actor.parameters())
    with pytest.raises(ValueError, match="normalize_obs needs"):
        DDPG(5, 2, config=cfg)
    with pytest.raises(ValueError, match="positive"):
        DDPG(5, 2, config=cfg, obs_offset=offset, obs_scale=np.zeros(5))
    with pytest.raises(ValueError, match="shape"):
        DDPG(5, 2, config=cfg, obs_offset=offset[:3], obs_scale=scale[:3])


def test_preactivation_penalty_by_hand_and_in_the_update():
    from dlo_course.ddpg import preactivation_penalty
    u = torch.tensor([[1.0, -3.0], [0.0, 2.0]])
    assert preactivation_penalty(u, 0.5).item() == pytest.approx(0.5 * (1 + 9 + 0 + 4) / 4)
    # A saturated actor: the tanh has no gradient left, only the penalty pulls it back.
    batch = random_batch(np.random.default_rng(0))
    for weight, expect_shrink in ((0.0, False), (1.0, True)):
        torch.manual_seed(0)
        cfg = DDPGConfig(hidden_sizes=(16, 16), batch_size=8, actor_lr=1e-2,
                         preactivation_l2=weight)
        agent = DDPG(5, 2, config=cfg)
        with torch.no_grad():
            agent.actor.net[-1].bias.fill_(8.0)  # tanh(8) = 0.9999998
        obs = torch.as_tensor(batch["obs"], dtype=torch.float32)
        before = agent.actor.preactivation(obs).abs().mean().item()
        for _ in range(20):
            agent.update(batch)
        after = agent.actor.preactivation(obs).abs().mean().item()
        assert (after < before - 0.1) == expect_shrink, (weight, before, after)
    with pytest.raises(ValueError):
        DDPGConfig(preactivation_l2=-1.0)
