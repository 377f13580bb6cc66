"""Diagnostics of a DDPG agent that does not learn (lesson 15).

The course's first run on the rod with the paper's settings on two cores did not learn
(``benchmarks/results/dlo_nodes4_2ranks.md``): half of the stored action components sat at
+-1, the actor's tanh was saturated, and the critic's gradient no longer reached it. These
functions make those measurements on any agent:

* :func:`saturation_report`: how saturated an actor's tanh is on a batch of observations
  (e.g. those of its replay buffer), from its pre-activation u (:meth:`Actor.preactivation`);
* :func:`bound_share`: the share of stored (noisy, clipped) actions at the action bounds;
* :func:`discounted_returns` and :func:`critic_check`: the critic's Q(s, a) beside the
  discounted returns actually observed after (s, a) (a Monte-Carlo check of the critic);
* :func:`record_episode`: one episode of a deterministic actor, for that check;
* :func:`read_progress_file`, :func:`run_buffer`: a progress CSV by its path (the benchmark
  files) and the replay buffer a finished run saved with its resume state.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

from dlo_course.ddpg import policy_action


@torch.no_grad()
def saturation_report(actor: torch.nn.Module, obs: Any, threshold: float = 0.99
                      ) -> dict[str, Any]:
    """How saturated the actor's tanh is on a batch of observations.

    The actor outputs ``bias + scale * tanh(u)``; the gradient the critic sends to the actor
    is multiplied by ``tanh'(u) = 1 - tanh(u)**2``, which is below 0.02 once
    ``|tanh(u)| > 0.99`` (``|u| > 2.65``). A saturated actor no longer hears its critic.

    Args:
        actor: an :class:`~dlo_course.ddpg.Actor` (anything with ``preactivation(obs)``).
        obs: (N, obs_dim) observations, e.g. the ``obs`` of a replay buffer.
        threshold: a component counts as saturated when ``|tanh(u)| > threshold``.

    Returns:
        dict: ``saturated`` (float, share of all action components beyond the threshold),
        ``saturated_per_dim`` ((act_dim,) float64, the same per action component),
        ``preactivation_abs_mean`` (float, mean ``|u|``) and ``tanh_gradient`` (float, mean
        ``1 - tanh(u)**2``: the share of the critic's gradient that passes the tanh).
    """
    u = actor.preactivation(torch.as_tensor(np.asarray(obs, dtype=np.float32)))
    squashed = torch.tanh(u).double()
    beyond = (squashed.abs() > threshold).double()
    return {"saturated": beyond.mean().item(),
            "saturated_per_dim": beyond.mean(dim=0).numpy(),
            "preactivation_abs_mean": u.double().abs().mean().item(),
            "tanh_gradient": (1.0 - squashed ** 2).mean().item()}


def bound_share(actions: Any, low: Any, high: Any, threshold: float = 0.99) -> np.ndarray:
    """(act_dim,) float64: per action component, the share of ``actions`` (N, act_dim) whose
    normalised value ``(a - centre) / half_width`` lies beyond ``threshold`` in absolute
    value: stored actions (noise included, clipped to the bounds) at or near a bound."""
    actions = np.asarray(actions, dtype=np.float64)
    low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    normalised = (actions - (high + low) / 2) / ((high - low) / 2)
    return np.mean(np.abs(normalised) > threshold, axis=0)


def discounted_returns(rewards: Sequence[float], gamma: float, bootstrap: float = 0.0
                       ) -> np.ndarray:
    """The discounted return from every step of one episode: G_t = r_t + gamma * G_{t+1}.

    Args:
        rewards: r_0 ... r_{T-1} of one episode, in order.
        gamma: discount factor.
        bootstrap: G_T, the value of what follows the last step: 0 for an episode that
            terminated (or to ignore the tail of a truncated one, which then makes the last
            returns too small in magnitude).

    Returns:
        (T,) float64 array, G_0 first.
    """
    rewards = np.asarray(rewards, dtype=np.float64).reshape(-1)
    out = np.empty_like(rewards)
    running = float(bootstrap)
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + gamma * running
        out[t] = running
    return out


@torch.no_grad()
def record_episode(env: Any, actor: torch.nn.Module, seed: int | None = None,
                   max_steps: int | None = None) -> dict[str, np.ndarray]:
    """Play one episode with the deterministic actor (no noise) and keep what happened.

    Args:
        env: a Gymnasium environment.
        actor: maps observations to actions (:func:`~dlo_course.ddpg.policy_action`).
        seed: passed to ``env.reset``.
        max_steps: stop after this many actions at the latest (``None``: when the
            environment ends the episode).

    Returns:
        dict of arrays: ``obs`` (T, obs_dim) and ``act`` (T, act_dim) float32, ``rew`` (T,)
        float64, and ``terminated`` (bool: the last step reached a terminal state).
    """
    obs, _ = env.reset(seed=seed)
    observations, actions, rewards, terminated = [], [], [], False
    while max_steps is None or len(rewards) < max_steps:
        action = policy_action(actor, obs)
        next_obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(np.asarray(obs, dtype=np.float32))
        actions.append(np.asarray(action, dtype=np.float32))
        rewards.append(float(reward))
        obs = next_obs
        if terminated or truncated:
            break
    return {"obs": np.array(observations), "act": np.array(actions),
            "rew": np.array(rewards, dtype=np.float64), "terminated": np.array(bool(terminated))}


@torch.no_grad()
def critic_check(critic: torch.nn.Module, obs: Any, act: Any, returns: Any) -> dict[str, Any]:
    """The critic's Q(s, a) beside the discounted returns observed after (s, a).

    A critic that has learned Q of the policy that produced the returns agrees with them on
    average (the returns are single noisy samples); a constant offset means a biased critic,
    a low correlation one that does not tell good states and actions from bad ones.

    Args:
        critic: a :class:`~dlo_course.ddpg.Critic`.
        obs: (N, obs_dim) observations; act: (N, act_dim) the actions taken in them.
        returns: (N,) the discounted returns that followed (:func:`discounted_returns`).

    Returns:
        dict: ``q`` ((N,) float64), ``correlation`` (Pearson, NaN if either side is
        constant), ``mean_q``, ``mean_return`` and ``bias`` (``mean_q - mean_return``).
    """
    q = critic(torch.as_tensor(np.asarray(obs, dtype=np.float32)),
               torch.as_tensor(np.asarray(act, dtype=np.float32))).double().numpy().reshape(-1)
    returns = np.asarray(returns, dtype=np.float64).reshape(-1)
    if q.shape != returns.shape:
        raise ValueError(f"{q.shape[0]} Q-values but {returns.shape[0]} returns")
    spread = q.std() * returns.std()
    correlation = float(np.mean((q - q.mean()) * (returns - returns.mean())) / spread) \
        if spread > 0 else float("nan")
    return {"q": q, "correlation": correlation, "mean_q": float(q.mean()),
            "mean_return": float(returns.mean()), "bias": float(q.mean() - returns.mean())}


def read_progress_file(path: str | Path) -> dict[str, np.ndarray]:
    """The columns of a progress CSV given by its path (e.g. a benchmark's
    ``benchmarks/results/*_progress.csv``), as float arrays; empty cells become NaN. For a
    run directory use :func:`dlo_course.rundir.read_progress`."""
    with Path(path).open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path} has no rows")
    return {key: np.array([float(r[key]) if r[key] not in ("", None) else np.nan
                           for r in rows]) for key in rows[0]}


def run_buffer(run_dir: str | Path, rank: int = 0) -> dict[str, np.ndarray]:
    """The replay buffer of one agent (MPI rank) of a training run, as saved with its latest
    resume state (``checkpoints/``; :func:`dlo_course.rundir.save_resume_state`): a dict of
    float32 arrays ``obs``, ``act``, ``rew``, ``next_obs``, ``done`` of the filled rows, in
    the order they were written (ring order once the buffer has wrapped)."""
    from dlo_course import rundir

    root = Path(run_dir) / rundir.RESUME_DIR
    name = rundir.read_json(root / rundir.RESUME_POINTER)["checkpoint"]
    state = torch.load(root / name / rundir._rank_state_file(rank), weights_only=False)["buffer"]
    return {key: np.asarray(state[key]) for key in ("obs", "act", "rew", "next_obs", "done")}
