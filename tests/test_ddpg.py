import numpy as np
import pytest
import torch

import dlo_course.ddpg as ddpg_module
from dlo_course.config import DDPGConfig
from dlo_course.ddpg import (DDPG, Actor, Critic, bellman_target, critic_loss, load_network,
                             polyak_update, policy_loss, save_network)

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


def test_policy_action_is_numpy_in_numpy_out_without_gradient():
    from dlo_course.ddpg import policy_action

    agent = DDPG(5, 2, action_low=[-2, -1], action_high=[2, 1], config=SMALL)
    obs = np.random.default_rng(0).normal(size=(3, 5))  # float64: cast to the networks' float32
    batch = policy_action(agent.actor, obs)
    assert isinstance(batch, np.ndarray) and batch.shape == (3, 2) and batch.dtype == np.float32
    single = policy_action(agent.actor, obs[0])
    assert single.shape == (2,)  # no batch axis added
    with torch.no_grad():
        expected = agent.actor(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    np.testing.assert_array_equal(batch, expected)
    # Without noise the agent's action is the policy's, clipped (a no-op inside the bounds).
    np.testing.assert_array_equal(agent.act(obs[0]), single)


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


# --- TD3's fixes (course options, off by default: the paper has none of them) ---

TD3 = DDPGConfig(hidden_sizes=(16, 16), batch_size=8, twin_critics=True, policy_delay=2,
                 target_noise=0.2, target_noise_clip=0.5)


def paper_update(agent, batch):
    """The paper's DDPG update written out plainly (the code before the TD3 options), on
    ``agent``'s networks and optimisers."""
    obs, act, next_obs = (torch.as_tensor(batch[k], dtype=torch.float32)
                          for k in ("obs", "act", "next_obs"))
    rew = torch.as_tensor(batch["rew"], dtype=torch.float32).reshape(-1, 1)
    done = torch.as_tensor(batch["done"], dtype=torch.float32).reshape(-1, 1)
    gamma, tau = agent.config.gamma, agent.config.tau
    with torch.no_grad():
        y = rew + gamma * agent.critic_target(next_obs, agent.actor_target(next_obs)) * (1 - done)
    q = agent.critic(obs, act)
    loss_q = ((q - y) ** 2).mean()
    agent.critic_optimizer.zero_grad()
    loss_q.backward()
    agent.critic_optimizer.step()
    agent.critic.requires_grad_(False)
    loss_pi = -agent.critic(obs, agent.actor(obs)).mean()
    agent.actor_optimizer.zero_grad()
    loss_pi.backward()
    agent.actor_optimizer.step()
    agent.critic.requires_grad_(True)
    with torch.no_grad():
        for target, net in ((agent.actor_target, agent.actor), (agent.critic_target, agent.critic)):
            for w_target, w in zip(target.parameters(), net.parameters()):
                w_target.mul_(1 - tau).add_(w, alpha=tau)
    return {"critic_loss": loss_q.item(), "policy_loss": loss_pi.item(), "q_mean": q.mean().item()}


def test_with_the_options_off_the_update_is_the_papers_bit_for_bit():
    import copy
    torch.manual_seed(0)
    agent = DDPG(5, 2, config=SMALL)
    reference = copy.deepcopy(agent)  # same weights, its own optimisers
    rng = np.random.default_rng(0)
    for _ in range(3):
        batch = random_batch(rng)
        assert agent.update(batch) == paper_update(reference, batch)
    for name in ("actor", "critic", "actor_target", "critic_target"):
        for p, q in zip(getattr(agent, name).parameters(), getattr(reference, name).parameters()):
            assert torch.equal(p, q), name


def test_td3_options_are_off_by_default():
    c = DDPGConfig()
    assert (c.twin_critics, c.policy_delay, c.target_noise) == (False, 1, 0.0)
    agent = DDPG(5, 2, config=SMALL)
    assert agent.critic2 is None and agent.critics == [agent.critic]
    assert not any(key.startswith("critic2") for key in agent.state_dict())
    for bad in (dict(policy_delay=0), dict(target_noise=-0.1), dict(target_noise_clip=0.0)):
        with pytest.raises(ValueError):
            DDPGConfig(**bad)


def test_twin_critics_target_is_the_min_of_the_two_target_critics():
    torch.manual_seed(0)
    agent = DDPG(5, 2, config=DDPGConfig(hidden_sizes=(16, 16), twin_critics=True))
    next_obs = torch.randn(64, 5)
    next_act = agent.actor_target(next_obs)
    q1, q2 = agent.critic_target(next_obs, next_act), agent.critic2_target(next_obs, next_act)
    assert (q1 < q2).any() and (q2 < q1).any()  # both critics are the smaller somewhere
    torch.testing.assert_close(agent.target_value(next_obs), torch.min(q1, q2),
                               rtol=0, atol=0)
    # The second critic is made after the first: actor and first critic are the same as
    # without it.
    torch.manual_seed(0)
    single = DDPG(5, 2, config=DDPGConfig(hidden_sizes=(16, 16)))
    for a, b in ((agent.actor, single.actor), (agent.critic, single.critic)):
        assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))
    assert not torch.equal(agent.critic.net[0].weight, agent.critic2.net[0].weight)


def test_twin_critics_both_learn_and_are_saved():
    torch.manual_seed(0)
    cfg = DDPGConfig(hidden_sizes=(16, 16), batch_size=8, twin_critics=True)
    agent = DDPG(5, 2, config=cfg)
    before = [p.detach().clone() for p in agent.critic2.parameters()]
    calls = []
    agent.update(random_batch(np.random.default_rng(0)), grad_reducer=calls.append)
    assert calls == [agent.critic, agent.critic2, agent.actor]
    assert all(not torch.equal(p, q) for p, q in zip(before, agent.critic2.parameters()))
    for t_new, p_new, t_old in zip(agent.critic2_target.parameters(), agent.critic2.parameters(),
                                   before):  # the target started as a copy of the critic
        torch.testing.assert_close(t_new, cfg.tau * p_new + (1 - cfg.tau) * t_old)

    copy_ = DDPG(5, 2, config=cfg)
    copy_.load_state_dict(agent.state_dict())
    batch = random_batch(np.random.default_rng(1))
    assert agent.update(batch) == copy_.update(batch)
    for name in ("critic2", "critic2_target"):
        for p, q in zip(getattr(agent, name).parameters(), getattr(copy_, name).parameters()):
            assert torch.equal(p, q)
    with pytest.raises(ValueError, match="twin critics"):
        DDPG(5, 2, config=SMALL).load_state_dict(agent.state_dict())


def test_policy_delay_skips_actor_and_target_updates():
    torch.manual_seed(0)
    agent = DDPG(5, 2, config=DDPGConfig(hidden_sizes=(16, 16), batch_size=8, policy_delay=2))
    rng = np.random.default_rng(0)

    def snapshot():
        return {name: [p.detach().clone() for p in getattr(agent, name).parameters()]
                for name in ("actor", "critic", "actor_target", "critic_target")}

    def changed(old, name):
        return any(not torch.equal(p, q) for p, q in zip(old[name],
                                                         getattr(agent, name).parameters()))

    resumed = None
    for update in (1, 2, 3, 4):
        before, calls = snapshot(), []
        stats = agent.update(random_batch(rng), grad_reducer=calls.append)
        actor_turn = update % 2 == 0
        assert changed(before, "critic")
        assert changed(before, "actor") == changed(before, "actor_target") == \
            changed(before, "critic_target") == actor_turn
        assert calls == ([agent.critic, agent.actor] if actor_turn else [agent.critic])
        assert ("policy_loss" in stats) == actor_turn
        if update == 1:  # the update count is part of the saved state
            resumed = DDPG(5, 2, config=agent.config)
            resumed.load_state_dict(agent.state_dict())
    assert resumed.updates == 1 and agent.updates == 4
    assert "policy_loss" in resumed.update(random_batch(rng))


def test_target_noise_is_clipped():
    from dlo_course.ddpg import smoothed_target_action
    action = torch.tensor([[0.0, 1.5], [1.9, -0.5]])
    scale, bias = torch.tensor([2.0, 1.0]), torch.tensor([0.0, 1.0])  # bounds [-2, 2], [0, 2]
    noise = torch.tensor([[100.0, -0.1], [0.25, -100.0]])
    # eps clipped to +-0.3, times the scale, then the action clipped to the bounds
    torch.testing.assert_close(smoothed_target_action(action, noise, 0.3, scale, bias),
                               torch.tensor([[0.6, 1.4], [2.0, 0.0]]))

    # In the agent: noise drawn from torch's generator, then the same smoothing.
    cfg = DDPGConfig(hidden_sizes=(16, 16), target_noise=5.0, target_noise_clip=0.1)
    agent = DDPG(5, 2, action_low=[-2, -1], action_high=[2, 1], config=cfg)
    next_obs = torch.randn(32, 5)
    torch.manual_seed(7)
    value = agent.target_value(next_obs)
    torch.manual_seed(7)
    mu = agent.actor_target(next_obs)
    smoothed = smoothed_target_action(mu, 5.0 * torch.randn_like(mu), 0.1,
                                      agent.actor.action_scale, agent.actor.action_bias)
    assert torch.all((smoothed - mu).abs() <= 0.1 * agent.actor.action_scale + 1e-6)
    assert torch.equal(value, agent.critic_target(next_obs, smoothed))
    assert not torch.equal(value, agent.critic_target(next_obs, mu))


def test_all_td3_options_together_with_bigger_batches():
    torch.manual_seed(0)
    agent = DDPG(5, 2, config=TD3)
    rng = np.random.default_rng(0)
    stats = [agent.update(random_batch(rng, b=64)) for _ in range(4)]
    assert [("policy_loss" in s) for s in stats] == [False, True, False, True]
    assert all(np.isfinite(v) for s in stats for v in s.values())


def test_update_rules_replace_the_formulas_without_patching_the_library():
    """An agent built with other rules uses them; the next agent gets the paper's again."""
    calls = []

    def counting_critic_loss(q, q_target):
        calls.append("critic_loss")
        return ddpg_module.critic_loss(q, q_target)

    def frozen_targets(target, source, tau):
        calls.append("polyak_update")  # and leave the targets where they are

    torch.manual_seed(0)
    rules = ddpg_module.UpdateRules(critic_loss=counting_critic_loss, polyak_update=frozen_targets)
    agent = ddpg_module.DDPG(3, 1, rules=rules)
    before = [p.clone() for p in agent.actor_target.parameters()]
    rng = np.random.default_rng(0)
    batch = {"obs": rng.normal(size=(8, 3)), "act": rng.uniform(-1, 1, (8, 1)),
             "rew": rng.normal(size=8), "next_obs": rng.normal(size=(8, 3)),
             "done": np.zeros(8)}
    agent.update(batch)
    assert calls == ["critic_loss", "polyak_update", "polyak_update"]
    for old, new in zip(before, agent.actor_target.parameters()):
        torch.testing.assert_close(old, new)
    assert ddpg_module.DDPG(3, 1).rules == ddpg_module.UpdateRules()
    assert ddpg_module.UpdateRules().critic_loss is ddpg_module.critic_loss


def test_td3_target_is_what_the_update_regresses_on():
    """ddpg.td3_target (lesson 15) equals DDPG.update's label with TD3's options: the same
    noise from torch's generator, the smaller of the two target critics, the done mask."""
    from dlo_course.ddpg import td3_target
    cfg = DDPGConfig(hidden_sizes=(16, 16), twin_critics=True, target_noise=0.3,
                     target_noise_clip=0.2, gamma=0.9)
    torch.manual_seed(3)
    agent = DDPG(5, 2, action_low=[-2, -1], action_high=[2, 1], config=cfg)
    with torch.no_grad():  # targets that differ from each other and from the networks
        for p in agent.critic2_target.parameters():
            p.add_(0.2 * torch.randn(p.shape))
    next_obs, rew = torch.randn(32, 5), torch.randn(32, 1)
    done = (torch.arange(32) % 3 == 0).float().reshape(32, 1)
    torch.manual_seed(11)
    expected = bellman_target(rew, agent.target_value(next_obs), done, cfg.gamma)
    torch.manual_seed(11)
    noise = cfg.target_noise * torch.randn(32, 2)
    got = td3_target(rew, next_obs, done, cfg.gamma, agent.actor_target,
                     [agent.critic_target, agent.critic2_target], noise, cfg.target_noise_clip)
    assert torch.equal(got, expected) and not got.requires_grad
    # without noise and with one critic: the paper's target
    plain = td3_target(rew, next_obs, done, 0.9, agent.actor_target, [agent.critic_target])
    with torch.no_grad():
        paper = bellman_target(rew, agent.critic_target(next_obs, agent.actor_target(next_obs)),
                               done, 0.9)
    assert torch.equal(plain, paper)


def test_actor_update_due_is_the_updates_decision():
    from dlo_course.ddpg import actor_update_due
    assert [actor_update_due(k, 1) for k in (1, 2, 3)] == [True, True, True]
    assert [actor_update_due(k, 3) for k in range(1, 8)] == \
        [False, False, True, False, False, True, False]
    torch.manual_seed(0)
    agent = DDPG(5, 2, config=DDPGConfig(hidden_sizes=(8,), batch_size=8, policy_delay=3))
    rng = np.random.default_rng(1)
    steps = [("policy_loss" in agent.update(random_batch(rng))) for _ in range(7)]
    assert steps == [actor_update_due(k, 3) for k in range(1, 8)]
