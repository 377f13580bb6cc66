"""Grading: lesson 15, why DDPG stalls (references: dlo_course.diagnostics.saturation_report,
dlo_course.diagnostics.discounted_returns, dlo_course.ddpg.smoothed_target_action,
dlo_course.ddpg.td3_target, dlo_course.ddpg.actor_update_due)."""

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


# ------------------------------------------------------------- discounted_returns

RETURN_CASES = [(0, 5, 0.9, 0.0), (1, 30, 0.99, 0.0), (2, 12, 0.5, -4.0), (3, 1, 0.99, 7.5),
                (4, 0, 0.9, 3.0)]


def probe_discounted_returns(fn):
    out = []
    for seed, length, gamma, bootstrap in RETURN_CASES:
        rewards = list(np.random.default_rng(seed).normal(size=length))  # a plain list
        out.append(np.asarray(fn(rewards, gamma, bootstrap=bootstrap), dtype=np.float64))
    return out


@pytest.mark.exercise("discounted_returns", points=2,
                      reference="dlo_course.diagnostics.discounted_returns")
def test_discounted_returns(student):
    got = student.run(probe_discounted_returns)
    want = probe_discounted_returns(diagnostics.discounted_returns)
    for (seed, length, gamma, bootstrap), mine, ref in zip(RETURN_CASES, got, want, strict=True):
        where = f"{length} rewards, gamma {gamma}, bootstrap {bootstrap}"
        assert mine.shape == ref.shape, f"{where}: shape {mine.shape}, expected {ref.shape} " \
                                        f"(one return per step)"
        np.testing.assert_allclose(mine, ref, rtol=1e-9, atol=1e-12,
                                   err_msg=f"{where}: G_t = r_t + gamma * G_(t+1), G_T = "
                                           f"bootstrap")


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


# ------------------------------------------------------------ actor_update_due

DELAY_GRID = [(k, d) for d in (1, 2, 3, 5) for k in range(1, 13)]


def probe_actor_update_due(fn):
    return [bool(fn(k, d)) for k, d in DELAY_GRID]


@pytest.mark.exercise("actor_update_due", points=1,
                      reference=("dlo_course.ddpg.actor_update_due", "dlo_course.ddpg.DDPG.update"))
def test_actor_update_due(student):
    got = student.run(probe_actor_update_due)
    want = probe_actor_update_due(ddpg.actor_update_due)
    wrong = [f"update {k}, delay {d}: {g} (expected {w})"
             for (k, d), g, w in zip(DELAY_GRID, got, want, strict=True) if g != w]
    assert not wrong, "the actor steps at critic updates d, 2d, 3d, ...: " + "; ".join(wrong[:4])
