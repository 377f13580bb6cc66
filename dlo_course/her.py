"""Hindsight experience replay (HER): learning from the goals the rod actually reached.

Most training episodes on the rod end far from their goal, so almost every stored reward says
"far", and the critic learns little about what reaching a shape looks like. Andrychowicz et al.
(2017, "Hindsight Experience Replay") observed that a failed episode is still a perfect
demonstration of how to reach *the shapes it passed through*. The rod's task allows replaying
it with another goal at no simulator cost:

* the goal P_d is part of the observation, ``[ tip (3) | tip velocity (3) | P_c (3m) | P_d (3m) ]``,
  and nothing else in the observation depends on it (the rod's motion does not depend on the
  goal);
* the reward ``-mean_i ||P_c,i - P_d,i||`` and the termination (that distance below the
  threshold) can be recomputed for any goal from the next observation's P_c.

So each real transition (s, a, r, s', d) is stored again ``k`` times, each time with a goal g
that the rod reached later in the same episode (the "future" strategy of the paper): g is the
P_c of the next observation of a step t' >= t, and

    s_g = s with P_d := g,   s'_g = s' with P_d := g,
    r_g = -mean_i ||P_c,i(s') - g_i||,   d_g = (mean_i ||P_c,i(s') - g_i|| < threshold).

With t' = t the goal is where this very action took the rod: the copy is a success (d_g = 1).

Shapes: ``T`` is the number of transitions of the episode, ``m`` the number of selected nodes
(``n_nodes``), ``obs_dim`` the observation length (6 + 6m for the rod), ``act_dim`` the action
length, ``N = T * k`` the number of relabelled copies.

The functions are pure (:func:`goal_distance`, :func:`relabel`), apart from
:func:`future_goal_steps` which draws from the generator it is given;
:class:`HindsightRelabeller` holds that generator (seeded, saved in the resume state) for the
trainer (``TrainConfig.her_k``).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from dlo_course.task import ObservationLayout, reached, split_observation


def split_goal_obs(obs: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """The achieved and desired node positions inside observations: in the words of
    goal-conditioned learning, P_c and P_d of :func:`dlo_course.task.split_observation`.

    Args:
        obs: (..., 6 + 6m) observations of ``DLOShape-v0``.
        n_nodes: m.

    Returns:
        ``(achieved, desired)``, views of ``obs`` of shape (..., m, 3) each: P_c and P_d.
    """
    parts = split_observation(np.asarray(obs), n_nodes)
    return parts.current, parts.desired


def goal_distance(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """Mean Euclidean distance between node positions, for many pairs at once.

    The same arithmetic as :func:`dlo_course.env.mean_node_distance` (the environment's reward
    and termination), in float64 as there, vectorised over the leading axes.

    Args:
        achieved: (..., m, 3) current node positions P_c.
        desired: (..., m, 3) desired node positions P_d.

    Returns:
        (...) float64 distances in metres.
    """
    diff = np.asarray(achieved, dtype=np.float64) - np.asarray(desired, dtype=np.float64)
    return np.mean(np.linalg.norm(diff, axis=-1), axis=-1)


def future_goal_steps(episode_length: int, k: int, rng: np.random.Generator
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The "future" strategy: for every step t, k steps t' drawn uniformly from t ... T - 1.

    Args:
        episode_length: T, the number of transitions of the episode.
        k: relabelled copies per transition.
        rng: the generator to draw from.

    Returns:
        ``(steps, goal_steps)``, int64 arrays of shape (T * k,): copy i replays transition
        ``steps[i]`` with the goal reached at step ``goal_steps[i] >= steps[i]``.
    """
    steps = np.repeat(np.arange(episode_length), k)
    goal_steps = rng.integers(steps, episode_length)  # high is exclusive: t' in [t, T)
    return steps, goal_steps


def relabel(obs: np.ndarray, act: np.ndarray, next_obs: np.ndarray, steps: np.ndarray,
            goal_steps: np.ndarray, n_nodes: int, threshold: float) -> dict[str, np.ndarray]:
    """Copies of an episode's transitions with substituted goals, rewards and done flags.

    Args:
        obs: (T, obs_dim) observations s_t of one episode, in order.
        act: (T, act_dim) actions a_t.
        next_obs: (T, obs_dim) next observations s'_t.
        steps: (N,) which transition each copy replays.
        goal_steps: (N,) for each copy, the step t' >= steps whose achieved P_c (in
            ``next_obs[t']``) becomes the goal.
        n_nodes: m; the observations end with ``[P_c (3m) | P_d (3m)]``.
        threshold: success distance of the environment (m).

    Returns:
        A dict of float32 arrays, ready for :meth:`ReplayBuffer.add`: ``obs`` (N, obs_dim),
        ``act`` (N, act_dim), ``rew`` (N,), ``next_obs`` (N, obs_dim), ``done`` (N,).
    """
    obs, act, next_obs = np.asarray(obs), np.asarray(act), np.asarray(next_obs)
    steps, goal_steps = np.asarray(steps), np.asarray(goal_steps)
    T = len(obs)
    if next_obs.shape != obs.shape or len(act) != T:
        raise ValueError(f"obs {obs.shape}, act {act.shape} and next_obs {next_obs.shape} "
                         "must describe the same T transitions")
    if steps.shape != goal_steps.shape:
        raise ValueError("steps and goal_steps must have the same shape")
    if np.any(steps < 0) or np.any(goal_steps >= T) or np.any(goal_steps < steps):
        raise ValueError("every goal must come from the same episode, at or after the "
                         "transition it relabels (0 <= steps <= goal_steps < T)")

    achieved_next, _ = split_goal_obs(next_obs, n_nodes)  # (T, m, 3): where the rod got to
    goals = achieved_next[goal_steps]                       # (N, m, 3): the hindsight goals
    distance = goal_distance(achieved_next[steps], goals)   # (N,), as the env would compute

    def with_goal(o: np.ndarray) -> np.ndarray:  # (N, obs_dim) copies with P_d := goal
        o = o.astype(np.float32)  # fancy indexing already copied; never write into the episode
        o[:, ObservationLayout(n_nodes).desired] = goals.reshape(len(goals), -1)
        return o

    return {
        "obs": with_goal(obs[steps]),
        "act": act[steps].astype(np.float32),
        "rew": (-distance).astype(np.float32),
        "next_obs": with_goal(next_obs[steps]),
        "done": reached(distance, threshold).astype(np.float32),
    }


def goal_layout(env: gymnasium.Env) -> tuple[int, float]:
    """``(n_nodes, threshold)`` of a goal-reaching environment such as ``DLOShape-v0``.

    Hindsight relabelling needs an environment whose (unwrapped) object has attributes
    ``n_nodes`` and ``threshold``, whose observation ends with ``[P_c (3m) | P_d (3m)]``
    and whose reward is ``-goal_distance(P_c, P_d)``. Raises ``ValueError`` otherwise.
    """
    base = env.unwrapped
    n_nodes, threshold = getattr(base, "n_nodes", None), getattr(base, "threshold", None)
    name = env.spec.id if env.spec is not None else type(base).__name__
    if not isinstance(n_nodes, (int, np.integer)) or threshold is None:
        raise ValueError(f"hindsight relabelling (her_k > 0) needs a goal-reaching environment "
                         f"whose observation ends with [achieved P_c | desired P_d] and which "
                         f"declares n_nodes and threshold, like DLOShape-v0; {name} does not")
    shape = env.observation_space.shape
    if shape is None or len(shape) != 1 or shape[0] < 6 * n_nodes:
        raise ValueError(f"{name} declares {n_nodes} nodes but its observation space {shape} "
                         f"cannot end with [P_c | P_d] of {6 * n_nodes} values")
    return int(n_nodes), float(threshold)


class HindsightRelabeller:
    """Makes the relabelled copies of each training episode, with its own seeded generator.

    Args:
        n_nodes: m, the number of selected nodes.
        threshold: the environment's success distance (m).
        k: relabelled copies per real transition (``TrainConfig.her_k``; the HER paper's 4).
        seed: seed of the generator that draws the goal steps. Like the replay buffer and the
            noise, it owns its generator so that its state can be saved in the resume state (exact resume).
    """

    def __init__(self, n_nodes: int, threshold: float, k: int, seed: int | None = None) -> None:
        if k < 1:
            raise ValueError(f"k must be at least 1, got {k}")
        self.n_nodes, self.threshold, self.k = int(n_nodes), float(threshold), int(k)
        self.rng = np.random.default_rng(seed)

    @classmethod
    def for_env(cls, env: gymnasium.Env, k: int, seed: int | None = None
                ) -> "HindsightRelabeller":
        """A relabeller for ``env``'s layout and threshold (see :func:`goal_layout`)."""
        n_nodes, threshold = goal_layout(env)
        return cls(n_nodes, threshold, k, seed)

    def episode_copies(self, obs: np.ndarray, act: np.ndarray, rew: np.ndarray,
                       next_obs: np.ndarray) -> dict[str, np.ndarray]:
        """The ``T * k`` relabelled copies of one episode (see :func:`relabel`).

        Args:
            obs: (T, obs_dim), act: (T, act_dim), rew: (T,) the rewards the environment
                gave, next_obs: (T, obs_dim): the episode's real transitions, in order.

        Returns:
            As :func:`relabel`, with N = T * k.
        """
        # A relabelled reward is only right if the environment's reward is the distance
        # recomputed here; check it on the real goals, which costs nothing. Tolerance: the
        # observation holds float32 positions, the environment float64 ones.
        achieved, desired = split_goal_obs(next_obs, self.n_nodes)
        mismatch = np.max(np.abs(np.asarray(rew) + goal_distance(achieved, desired)),
                          initial=0.0)
        if mismatch > 1e-4:
            raise ValueError(f"hindsight relabelling: the environment's reward differs from "
                             f"-mean ||P_c - P_d|| recomputed from its observation by "
                             f"{mismatch:.3g}; its observation does not end with [P_c | P_d] "
                             f"for {self.n_nodes} nodes, or its reward is another one")
        steps, goal_steps = future_goal_steps(len(obs), self.k, self.rng)
        return relabel(obs, act, next_obs, steps, goal_steps, self.n_nodes, self.threshold)

    def state_dict(self) -> dict[str, Any]:
        return {"rng_state": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng_state"]
