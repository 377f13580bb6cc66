"""Grading: lesson 15, why DDPG stalls (references: dlo_course.diagnostics.saturation_report,
dlo_course.diagnostics.critic_check with discounted_returns, dlo_course.ddpg.smoothed_target_action,
dlo_course.ddpg.td3_target, dlo_course.ddpg.DDPG.update)."""

import numpy as np
import pytest
import torch

from dlo_course import ddpg, diagnostics

pytestmark = pytest.mark.notebook("15_why_ddpg_stalls")


# ------------------------------------------------------------- saturation_report

SATURATION_KEYS = ("saturated", "saturated_per_dim", "preactivation_abs_mean", "tanh_gradient")
# (seed, final_init, action bounds, threshold): from an untrained actor to a saturated one,
# on bounds other than [-1, 1] (the share is measured on tanh(u), not on the scaled action)
SATURATION_CASES = [(0, 3e-3, ([-1.0, -1.0], [1.0, 1.0]), 0.99),
                    (1, 1.0, ([-2.0, 0.0], [2.0, 1.0]), 0.99),
                    (2, 3.0, ([-2.0, -0.5], [2.0, 0.5]), 0.9),
                    (3, 10.0, ([0.0, -3.0], [4.0, 3.0]), 0.99)]


def saturation_case(seed, final_init, bounds):
    torch.manual_seed(seed)
    actor = ddpg.Actor(5, 2, action_low=bounds[0], action_high=bounds[1], hidden_sizes=(16, 16),
                       final_init=final_init)
    obs = np.random.default_rng(seed).normal(size=(64, 5)) * 3  # float64, as from NumPy
    return actor, obs


def probe_saturation_report(fn):
    out = []
    for seed, final_init, bounds, threshold in SATURATION_CASES:
        actor, obs = saturation_case(seed, final_init, bounds)
        report = fn(actor, obs, threshold=threshold)
        out.append({key: np.asarray(report[key], dtype=np.float64) for key in SATURATION_KEYS})
    return out


SATURATION_HINTS = {
    "saturated": "the share of all action components with |tanh(u)| > threshold",
    "saturated_per_dim": "the share per action component: a mean over the batch (axis 0), "
                         "one value per action component",
    "preactivation_abs_mean": "the mean of |u|, u = actor.preactivation(obs)",
    "tanh_gradient": "the mean of 1 - tanh(u)**2",
}


@pytest.mark.exercise("saturation_report", points=2,
                      reference="dlo_course.diagnostics.saturation_report")
def test_saturation_report(student):
    got = student.run(probe_saturation_report)
    want = probe_saturation_report(diagnostics.saturation_report)
    for case, mine, ref in zip(SATURATION_CASES, got, want, strict=True):
        for key in SATURATION_KEYS:
            assert np.shape(mine[key]) == np.shape(ref[key]), \
                f"{key}: shape {np.shape(mine[key])}, expected {np.shape(ref[key])} " \
                f"({SATURATION_HINTS[key]})"
            np.testing.assert_allclose(mine[key], ref[key], rtol=1e-5, atol=1e-7,
                                       err_msg=f"{key} (final_init {case[1]}, bounds "
                                               f"{case[2]}, threshold {case[3]}): "
                                               f"{SATURATION_HINTS[key]}")


# ------------------------------------------------------------------ overestimation

# (seed, episode lengths, gamma, compared): episodes shorter and longer than `compared`
OVER_CASES = [(0, (12, 9), 0.9, 6), (1, (30,), 0.99, 20), (2, (5, 14, 8), 0.95, 10)]


def overestimation_case(seed, lengths):
    """A critic and episodes of negative rewards, some of whose Q are above the returns."""
    torch.manual_seed(seed)
    critic = ddpg.Critic(3, 2, hidden_sizes=(16,), final_init=2.0)
    rng = np.random.default_rng(seed)
    episodes = [{"obs": rng.normal(size=(t, 3)).astype(np.float32),
                 "act": rng.uniform(-1, 1, (t, 2)).astype(np.float32),
                 "rew": -rng.uniform(0.0, 0.3, t)} for t in lengths]
    return critic, episodes


def reference_overestimation(critic, episodes, gamma, compared):
    """The library's measurement: diagnostics.discounted_returns over each whole episode,
    cut to its first `compared` steps, then diagnostics.critic_check."""
    returns = np.concatenate([diagnostics.discounted_returns(e["rew"], gamma)[:compared]
                              for e in episodes])
    check = diagnostics.critic_check(critic, np.concatenate([e["obs"][:compared] for e in episodes]),
                                     np.concatenate([e["act"][:compared] for e in episodes]),
                                     returns)
    return {"q": check["q"], "returns": returns, "bias": check["bias"],
            "overestimated": float(np.mean(check["q"] > returns))}


def probe_overestimation(fn):
    out = []
    for seed, lengths, gamma, compared in OVER_CASES:
        critic, episodes = overestimation_case(seed, lengths)
        got = fn(critic, episodes, gamma, compared)
        out.append({key: np.asarray(got[key], dtype=np.float64)
                    for key in ("q", "returns", "bias", "overestimated") if key in got})
    return out


@pytest.mark.exercise("overestimation", points=2,
                      reference=("dlo_course.diagnostics.critic_check",
                                 "dlo_course.diagnostics.discounted_returns"))
def test_overestimation(student):
    got = student.run(probe_overestimation)
    for (seed, lengths, gamma, compared), mine in zip(OVER_CASES, got, strict=True):
        critic, episodes = overestimation_case(seed, lengths)
        want = reference_overestimation(critic, episodes, gamma, compared)
        where = f"episodes of {lengths} steps, gamma {gamma}, compared {compared}"
        for key, hint in (("returns", "each episode's returns over the whole episode, then "
                                      "its first `compared` steps, the episodes in order"),
                          ("q", "Q(s_t, a_t) of the compared steps, in the same order"),
                          ("bias", "the mean of Q - G"),
                          ("overestimated", "the share of compared steps with Q > G")):
            assert key in mine, f"missing {key!r}"
            assert np.shape(mine[key]) == np.shape(want[key]), \
                f"{where}: {key} of shape {np.shape(mine[key])}, expected {np.shape(want[key])}"
            np.testing.assert_allclose(mine[key], want[key], rtol=1e-5, atol=1e-7,
                                       err_msg=f"{where}: {key}: {hint}")


# ------------------------------------------------------ smoothed_target_action

def smoothing_case(seed):
    gen = torch.Generator().manual_seed(seed)
    scale = torch.tensor([2.0, 0.5, 1.0])
    bias = torch.tensor([0.0, 0.5, -1.0])  # bounds [-2, 2], [0, 1], [-2, 0]
    action = bias + scale * (torch.rand(40, 3, generator=gen) * 2 - 1)
    noise = torch.randn(40, 3, generator=gen) * 0.8
    return action, noise, scale, bias


SMOOTHING_CASES = [(0, 0.5), (1, 0.3), (2, 10.0)]


def probe_smoothed_target_action(fn):
    out = []
    for seed, clip in SMOOTHING_CASES:
        action, noise, scale, bias = smoothing_case(seed)
        out.append(torch.as_tensor(fn(action, noise, clip, scale, bias)).detach().clone())
    return out


@pytest.mark.exercise("smoothed_target_action", points=2,
                      reference="dlo_course.ddpg.smoothed_target_action")
def test_smoothed_target_action(student):
    got = student.run(probe_smoothed_target_action)
    want = probe_smoothed_target_action(ddpg.smoothed_target_action)
    for (seed, clip), mine, ref in zip(SMOOTHING_CASES, got, want, strict=True):
        assert mine.shape == ref.shape, f"shape {tuple(mine.shape)}, expected {tuple(ref.shape)}"
        torch.testing.assert_close(
            mine.float(), ref, rtol=1e-6, atol=1e-6,
            msg=lambda m: f"noise clip {clip}: the noise clipped to [-c, c], times the action "
                          f"scale, added to the action, and the result clipped to "
                          f"[bias - scale, bias + scale]\n{m}")


# ------------------------------------------------------------------ td3_target

# (seed, number of target critics, smoothing noise?, noise clip, gamma)
TD3_CASES = [(0, 2, True, 0.5, 0.99), (1, 2, True, 0.2, 0.9), (2, 1, False, 0.5, 0.99),
             (3, 2, False, 0.5, 0.95), (4, 1, True, 0.3, 0.9)]


def td3_case(seed, n_critics, with_noise):
    torch.manual_seed(100 + seed)
    actor = ddpg.Actor(4, 2, action_low=[-2.0, 0.0], action_high=[2.0, 1.0], hidden_sizes=(16,),
                       final_init=1.0)  # large enough that clipping to the bounds matters
    critics = [ddpg.Critic(4, 2, hidden_sizes=(16,), final_init=1.0) for _ in range(n_critics)]
    for net in [actor, *critics]:
        net.requires_grad_(False)  # as target networks are
    gen = torch.Generator().manual_seed(seed)
    next_obs = torch.randn(32, 4, generator=gen)
    reward = torch.randn(32, 1, generator=gen)
    done = (torch.arange(32) % 5 == 0).float().reshape(32, 1)
    noise = torch.randn(32, 2, generator=gen) * 0.6 if with_noise else None
    return reward, next_obs, done, actor, critics, noise


def probe_td3_target(fn):
    out = []
    for seed, n_critics, with_noise, clip, gamma in TD3_CASES:
        reward, next_obs, done, actor, critics, noise = td3_case(seed, n_critics, with_noise)
        y = torch.as_tensor(fn(reward, next_obs, done, gamma, actor, critics, noise, clip))
        out.append({"y": y.detach().clone(), "requires_grad": bool(y.requires_grad)})
    return out


@pytest.mark.exercise("td3_target", points=3,
                      reference=("dlo_course.ddpg.td3_target", "dlo_course.ddpg.bellman_target",
                                 "dlo_course.ddpg.smoothed_target_action",
                                 "dlo_course.ddpg.DDPG.target_value"))
def test_td3_target(student):
    got = student.run(probe_td3_target)
    want = probe_td3_target(ddpg.td3_target)
    for (seed, n_critics, with_noise, clip, gamma), mine, ref in zip(TD3_CASES, got, want,
                                                                     strict=True):
        where = (f"{n_critics} target critic(s), {'with' if with_noise else 'without'} "
                 f"smoothing noise (clip {clip}), gamma {gamma}")
        assert mine["y"].shape == ref["y"].shape, \
            f"{where}: shape {tuple(mine['y'].shape)}, expected {tuple(ref['y'].shape)}"
        torch.testing.assert_close(
            mine["y"].float(), ref["y"], rtol=1e-5, atol=1e-6,
            msg=lambda m: f"{where}: y = r + gamma * (1 - d) * min over the target critics of "
                          f"Q'(s', a'), a' the smoothed target action (noise clipped, action "
                          f"clipped to the bounds)\n{m}")
        assert not mine["requires_grad"], f"{where}: the target is a label: compute it " \
                                          f"without gradient (torch.no_grad())"


# ------------------------------------------------------------------ td3_update

# (twin critics, policy delay, target noise, noise clip, pre-tanh penalty, updates)
UPDATE_CASES = [(True, 2, 0.2, 0.5, 0.01, 5), (False, 1, 0.0, 0.5, 0.0, 3),
                (True, 3, 0.1, 0.05, 0.0, 7), (False, 2, 0.3, 0.2, 0.05, 4)]
NETWORKS = ("actor", "critic", "critic2", "actor_target", "critic_target", "critic2_target")


def probe_td3_update(fn):
    """Agents updated by fn, from fixed weights, batches and noise seeds: whether the actor
    stepped at each update, the update count, and every network's weights after."""
    out = []
    for case, (twin, delay, noise, clip, penalty, updates) in enumerate(UPDATE_CASES):
        config = ddpg.DDPGConfig(hidden_sizes=(16,), twin_critics=twin, policy_delay=delay,
                                 target_noise=noise, target_noise_clip=clip,
                                 preactivation_l2=penalty)
        torch.manual_seed(case)
        agent = ddpg.DDPG(4, 2, action_low=[-2.0, 0.0], action_high=[2.0, 1.0], config=config)
        rng = np.random.default_rng(case)
        stepped = []
        for k in range(updates):
            batch = {"obs": rng.normal(size=(16, 4)), "act": rng.uniform(-1, 1, (16, 2)),
                     "rew": rng.normal(size=16), "next_obs": rng.normal(size=(16, 4)),
                     "done": (rng.uniform(size=16) < 0.2).astype(np.float64)}
            torch.manual_seed(1000 * case + k)  # the smoothing noise
            stepped.append(bool(fn(agent, batch)))
        weights = {name: [p.detach().clone().numpy() for p in getattr(agent, name).parameters()]
                   for name in NETWORKS if getattr(agent, name) is not None}
        out.append({"stepped": stepped, "updates": int(agent.updates), "weights": weights})
    return out


def library_td3_update(agent, batch):
    return "policy_loss" in agent.update(batch)


@pytest.mark.exercise("td3_update", points=2,
                      reference=("dlo_course.ddpg.DDPG.update", "dlo_course.ddpg.actor_update_due"))
def test_td3_update(student):
    got = student.run(probe_td3_update)
    want = probe_td3_update(library_td3_update)
    for case, mine, ref in zip(UPDATE_CASES, got, want, strict=True):
        twin, delay, noise, clip, penalty, updates = case
        where = (f"{'twin critics' if twin else 'one critic'}, policy delay {delay}, target "
                 f"noise {noise} (clip {clip}), penalty {penalty}")
        assert mine["updates"] == ref["updates"], \
            f"{where}: agent.updates is {mine['updates']} after {updates} updates"
        assert mine["stepped"] == ref["stepped"], (
            f"{where}: the actor stepped at {mine['stepped']}, expected {ref['stepped']} "
            f"(at critic updates d, 2d, 3d, ...)")
        for name, params in ref["weights"].items():
            for i, (a, b) in enumerate(zip(mine["weights"][name], params, strict=True)):
                np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6, err_msg=(
                    f"{where}: {name} differs after {updates} updates (parameter {i}): the "
                    f"critics' label, their steps, the actor's loss with the penalty, or the "
                    f"soft updates"))


@pytest.mark.exercise("prediction_overestimation", points=1)
def test_prediction_overestimation(written_answer):
    written_answer.check()
