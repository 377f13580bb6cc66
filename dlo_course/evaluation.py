"""The paper's test protocol (Section VI, Table I), in parallel over MPI ranks.

A trained actor is run without exploration noise for a number of test episodes of at most 30
actions each, stopped when the mean node distance falls below the threshold. For each setting
Table I reports:

* done %: the share of episodes that reached the threshold;
* mean ± σ and best of the *final* mean node distance (m) over the episodes.

We add a 95% confidence interval for done % (Wilson's score interval), which the paper does not
give: with 1000 episodes and 99% done it is about ±0.7 points, with 100 episodes about ±3.

Two ways to start an episode:

* with reinitialisation: the world is rebuilt before every episode;
* without: every episode starts from the shape the previous one ended in.

Episode ``i`` always gets goal ``goal_indices[i]``, drawn once from the seed. With
reinitialisation every episode is then independent, so any split of the episodes over MPI
ranks gives exactly the result of one process. Without, each rank runs its own chain of
episodes (rank r takes episodes r, r + N, r + 2N, ...), so the result depends on the number of
ranks as well as on the seed.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

import gymnasium
import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from dlo_course import mpi
from dlo_course.database import resolve_goals
from dlo_course.ddpg import Actor, load_network, policy_action
from dlo_course.rundir import ACTOR_FILE
from dlo_course.snapshot import fork_available, run_in_fork, torch_threads
from dlo_course.task import (NODE_COUNTS, TRAIN_THRESHOLD, nodes_of_observation_size,
                             observation_size, reached, split_observation)


# ------------------------------------------------------------------------------ statistics
@dataclass(frozen=True)
class EpisodeRecord:
    """The outcome of one test episode."""

    episode: int
    goal_index: int
    done: bool
    """The mean node distance went below the threshold."""
    final_distance: float
    """Mean node distance (m) when the episode stopped."""
    steps: int
    start_distance: float


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (default 95%), as fractions in [0, 1].

    Unlike the normal approximation it stays inside [0, 1] and behaves at 0% and 100%.
    """
    if n <= 0:
        raise ValueError("the interval needs at least one episode")
    if not 0 <= successes <= n:
        raise ValueError(f"successes must be within 0..{n}, got {successes}")
    p = successes / n
    denominator = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denominator
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


# Two-sided 95% quantiles of Student's t by degrees of freedom (scipy is not a dependency).
T_975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306,
         9: 2.262, 10: 2.228}


def rank_correlation(a, b) -> float:
    """Spearman's rank correlation of two (K,) score arrays (ties take their mean rank): 1 when
    ``a`` orders K agents as ``b`` does, -1 when reversed, about 0 when unrelated. How well a
    validation predicts the test (benchmarks/validation_vs_test.py)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1 or len(a) < 2:
        raise ValueError(f"want two (K,) arrays with K >= 2, got {a.shape} and {b.shape}")

    def ranks(x):
        order = np.argsort(x, kind="stable")
        r = np.empty(len(x))
        r[order] = np.arange(len(x), dtype=float)
        for value in np.unique(x):  # ties: their mean rank
            r[x == value] = r[x == value].mean()
        return r

    ra, rb = ranks(a), ranks(b)
    if ra.std() == 0 or rb.std() == 0:
        return float("nan")  # all scores equal: no order to compare
    return float(np.corrcoef(ra, rb)[0, 1])


def seed_interval(values, axis: int = 0) -> tuple:
    """Mean over independent runs (seeds) and its 95% t-interval.

    A done % measured over episodes has a binomial interval (:func:`wilson_interval`); the
    spread *between* training seeds is another source of variation, which only repeating the
    training measures. With ``n`` seeds the interval is ``mean ± t(n-1) · s / sqrt(n)``
    (``s``: sample standard deviation, ddof = 1): wide with 3 seeds (t = 4.3), as it should be.

    Args:
        values: (n, ...) one result per seed along ``axis`` (n from 2 to 11).
    Returns:
        (mean, low, high), each of the shape of ``values`` without ``axis`` (floats for 1-D).
    """
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[axis]
    if n - 1 not in T_975:
        raise ValueError(f"a t-interval needs 2 to {max(T_975) + 1} runs, got {n}")
    mean = values.mean(axis=axis)
    half = T_975[n - 1] * values.std(axis=axis, ddof=1) / np.sqrt(n)
    if mean.ndim == 0:
        return float(mean), float(mean - half), float(mean + half)
    return mean, mean - half, mean + half


@dataclass(frozen=True)
class Summary:
    """One row of Table I."""

    episodes: int
    done_percent: float
    done_ci_low: float
    """Lower end of the 95% Wilson interval of done %."""
    done_ci_high: float
    mean_distance: float
    std_distance: float
    """Population standard deviation (ddof = 0) of the final distances."""
    best_distance: float
    mean_steps: float

    def as_dict(self) -> dict:
        return asdict(self)


def summarize(records: Sequence[EpisodeRecord]) -> Summary:
    """Table I's statistics over test episodes (see the module docstring)."""
    if len(records) == 0:
        raise ValueError("no episodes to summarise")
    done = np.array([r.done for r in records], dtype=bool)
    final = np.array([r.final_distance for r in records], dtype=np.float64)
    low, high = wilson_interval(int(done.sum()), len(records))
    return Summary(
        episodes=len(records),
        done_percent=100.0 * done.mean(),
        done_ci_low=100.0 * low,
        done_ci_high=100.0 * high,
        mean_distance=float(final.mean()),
        std_distance=float(final.std()),
        best_distance=float(final.min()),
        mean_steps=float(np.mean([r.steps for r in records])),
    )


# ------------------------------------------------------------------------------ trained agents
class TrainedAgentError(ValueError):
    """A trained agent is missing, unreadable, or does not fit the task it is evaluated on."""


def load_actor(agent: str | Path, n_nodes: int | None = None):
    """Load the actor of a trained agent: a run directory, a shipped agent's folder (both
    hold ``actor.pt``) or an actor file; or an off-the-shelf agent's folder
    (``sb3_model.zip``, :mod:`dlo_course.baselines`), as a module of the same shapes.

    Args:
        n_nodes: when given, the actor must have been trained for that many nodes.

    Returns:
        (actor, n_nodes): the :class:`~dlo_course.ddpg.Actor` in eval mode and the number of
        nodes its observation implies.

    Raises:
        TrainedAgentError: with a message that says what is wrong and what to do.
    """
    from dlo_course import baselines

    path = Path(agent)
    if baselines.is_sb3_agent(path):  # an off-the-shelf agent, played like ours
        actor = baselines.load_sb3_actor(path)
    else:
        if path.is_dir():
            path = path / ACTOR_FILE
        if not path.is_file():
            raise TrainedAgentError(f"no trained agent at {agent}: expected a run directory "
                                    f"or an agent folder with {ACTOR_FILE} (or "
                                    f"{baselines.SB3_MODEL_FILE}), or the file itself "
                                    "(train one with `dlo-course train`)")
        try:
            actor = load_network(path)
        except Exception as err:  # torch and pickle raise many kinds
            raise TrainedAgentError(f"{path} is not a readable actor file "
                                    f"({type(err).__name__}: {err})") from err
        if not isinstance(actor, Actor):
            raise TrainedAgentError(f"{path} holds a {type(actor).__name__}, not an Actor")
    obs_dim = actor.init_kwargs["obs_dim"]
    act_dim = actor.init_kwargs["act_dim"]
    trained_nodes = nodes_of_observation_size(obs_dim)
    if act_dim != 3 or trained_nodes is None:
        sizes = "/".join(str(observation_size(n)) for n in NODE_COUNTS)
        raise TrainedAgentError(f"{path} was not trained on DLOShape-v0 (observation "
                                f"{obs_dim}, action {act_dim}; the rod needs {sizes} and 3)")
    if n_nodes is not None and n_nodes != trained_nodes:
        raise TrainedAgentError(f"{path} was trained for {trained_nodes} nodes (observation "
                                f"{obs_dim}) but is evaluated for {n_nodes} nodes "
                                f"(observation {observation_size(n_nodes)}); pass --nodes "
                                f"{trained_nodes} or another agent")
    actor.eval()
    return actor, trained_nodes


# ------------------------------------------------------------------------------ controllers
class Controller:
    """A hand-made policy with a memory, evaluated like a trained agent.

    A trained actor is a pure function of the observation; a classical controller (e.g.
    :class:`dlo_course.jacobian.JacobianController`) also remembers what it saw earlier in the
    episode. Wherever the protocol takes an actor (:func:`play_episode`, :func:`run_traces`,
    :func:`evaluate_thresholds`), it takes a ``Controller`` too, and then:

    * calls :meth:`bind` once with each environment it will act in (robot constants only);
    * calls :meth:`reset` with the first observation of every episode;
    * asks :meth:`act` for each action, one observation at a time.

    A controller must be deterministic given its episode, like an actor without noise: with
    reinitialisation, episodes with the same goal are simulated once (:func:`run_traces`).
    """

    n_nodes: int
    """Selected nodes of the observations it expects."""

    def bind(self, env) -> None:
        """Read what it needs of the robot from the environment (nothing by default)."""

    def reset(self, obs: np.ndarray) -> None:
        """Start an episode whose first observation is ``obs`` (6 + 6m,)."""
        raise NotImplementedError

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The action (3,) in [-1, 1] for the observation ``obs`` (6 + 6m,)."""
        raise NotImplementedError


# ------------------------------------------------------------------------------ goals
def goal_schedule(n_goals: int, episodes: int, seed: int) -> np.ndarray:
    """(episodes,) goal index of every test episode, drawn uniformly from the seed."""
    return np.random.default_rng(seed).integers(n_goals, size=episodes)


def recorded_tip_controller(database, n_nodes: int):
    """A privileged, hand-made baseline policy (not learned): it looks up which database goal
    the observation asks for and drives the tip at full speed straight to where the tip was
    when that goal was recorded. It cheats (it knows the database) and it ignores the rod's
    dynamics; lesson 10 and ``benchmarks/recorded_tip_controller.py`` use it as a yardstick.

    Args:
        database: a :class:`~dlo_course.database.Database` (its ``goals(n_nodes)`` and ``tip``).
        n_nodes: selected nodes in the observation.

    Returns:
        A module mapping (B, 6 + 6 n_nodes) observations to (B, 3) actions in [-1, 1].
    """
    from dlo_course.simulation import SimParams  # imports PyBullet: only when needed

    goals = torch.as_tensor(database.goals(n_nodes).reshape(len(database.tip), -1),
                            dtype=torch.float32)
    tips = torch.as_tensor(database.tip, dtype=torch.float32)
    # The largest tip displacement of one action (0.06 m): action +-1 covers it.
    params = SimParams()
    step = params.v_max * params.action_duration

    class RecordedTipController(nn.Module):
        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            parts = split_observation(obs, n_nodes)
            index = torch.cdist(parts.desired.flatten(1), goals).argmin(dim=1)
            return torch.clamp((tips[index] - parts.tip) / step, -1.0, 1.0)

    return RecordedTipController()


# ------------------------------------------------------------------------------ protocol
def play_episode(actor, env, obs: np.ndarray, max_steps: int) -> tuple[bool, int, dict]:
    """Run the deterministic policy from the environment's current state, just after a reset.

    Args:
        actor: a module mapping (1, obs_dim) observation tensors to (1, 3) actions, or a
            :class:`Controller` (reset with ``obs``, then asked for each action).
        env: the environment, reset; ``obs`` is the observation that reset returned.
        max_steps: at most this many actions.

    Returns:
        (done, steps, info): whether the threshold was reached, the actions taken, and the
        ``info`` of the last step.
    """
    done, distances, info = _play(actor, env, obs, max_steps)
    return done, len(distances), info


def _play(actor, env, obs: np.ndarray, max_steps: int) -> tuple[bool, list[float], dict]:
    """:func:`play_episode`, also returning the mean node distance after every action."""
    distances: list[float] = []
    info: dict = {}
    controller = isinstance(actor, Controller)
    if controller:
        actor.reset(obs)  # a controller's memory lasts one episode
    for _ in range(max_steps):
        if controller:
            action = actor.act(obs)
        else:
            action = policy_action(actor, obs[None])[0]  # a batch of one, as it always was
        obs, _, terminated, truncated, info = env.step(action)
        distances.append(float(info["distance"]))
        if terminated or truncated:
            return bool(terminated), distances, info
    return False, distances, info


@dataclass(frozen=True)
class EpisodeTrace:
    """What one test episode did, enough to score it at any threshold above the one it ran with.

    The environment stops an episode at its own threshold; at a larger threshold the same
    episode would have stopped at the first action that brought the distance below it, and
    everything up to that action is identical. So one episode run at 0.03 m gives both the
    0.03 m and the 0.05 m results of Table I (with reinitialisation, where episodes do not
    depend on each other).
    """

    start_distance: float
    distances: tuple[float, ...]
    """Mean node distance (m) after each action."""

    def record(self, episode: int, goal_index: int, threshold: float) -> EpisodeRecord:
        """The episode's outcome at ``threshold`` (not below the one it was run with)."""
        for steps, distance in enumerate(self.distances, start=1):
            if reached(distance, threshold):
                return EpisodeRecord(episode, goal_index, True, distance, steps,
                                     self.start_distance)
        final = self.distances[-1] if self.distances else self.start_distance
        return EpisodeRecord(episode, goal_index, False, final, len(self.distances),
                             self.start_distance)


def run_traces(actor, env, episode_ids: Sequence[int], goal_indices: np.ndarray,
               reinitialize: bool, max_steps: int, progress=None,
               fork: bool | None = None) -> list[EpisodeTrace]:
    """Run the given test episodes in order on one environment (one chain of episodes).

    With reinitialisation every episode starts from the same rebuilt world, and the policy
    and the simulation are deterministic, so two episodes with the same goal shape are the
    same episode: it is simulated once (the paper's test files repeat their goals). And the
    world is rebuilt and settled only once: each episode runs in a forked copy of the
    process, from that very state (:mod:`dlo_course.snapshot`), which gives the same
    episodes as a rebuild before each (tested bit for bit) at a fraction of the cost.
    Neither holds when the world itself is random (an environment with ``random_episodes``
    true: domain randomisation): then every episode is played, after its own rebuild. A
    wrapper that rewrites observations (e.g. noise on P_c) keeps the repeats but not the
    forks, since a forked episode starts past the wrappers.

    Args:
        actor: deterministic policy, a module mapping (1, obs_dim) tensors to (1, 3) actions,
            or a :class:`Controller` (bound to ``env`` by the caller).
        env: a :class:`~dlo_course.env.DLOShapeEnv` built with the test goals; it stops each
            episode at its own ``threshold``.
        episode_ids: global indices of the episodes this process runs.
        goal_indices: goal index of every episode (global, see :func:`goal_schedule`).
        reinitialize: rebuild the world before each episode, or continue from the last shape.
        max_steps: at most this many actions per episode.
        progress: an optional callable called once after each episode.
        fork: run the episodes with reinitialisation in forked copies of one settled world
            (``None``: wherever :func:`~dlo_course.snapshot.fork_available` and the scene has
            no GUI); ``False`` rebuilds the world before every episode.
    """
    rod = env.unwrapped
    # Repeats and forks rest on an episode being a function of its goal alone; a world drawn
    # at random (domain randomisation) breaks that. A forked episode starts from the rod's
    # own set_goal, past the wrappers: one that rewrites observations (noise) needs a reset.
    repeatable = reinitialize and not _random_episodes(env)
    if fork is None:
        fork = fork_available() and not getattr(getattr(rod, "scene", None), "gui", True)
    fork = bool(fork and repeatable and hasattr(rod, "set_goal")
                and not _rewrites_observations(env))
    # One torch thread, forked or not: a forked child can only compute on one (the parent's
    # OpenMP pool does not survive the fork, dlo_course.snapshot), so the rebuilt episodes do
    # too and give the same bits; a batch of one observation gains nothing from more.
    with torch_threads(1):
        return _run_chain(actor, env, rod, episode_ids, goal_indices, reinitialize, max_steps,
                          progress, fork, repeatable)


def _run_chain(actor, env, rod, episode_ids, goal_indices, reinitialize, max_steps, progress,
               fork, repeatable) -> list[EpisodeTrace]:
    settled = False  # with fork: the world has been rebuilt and settled once
    traces, seen = [], {}
    for i, episode in enumerate(episode_ids):
        goal_index = int(goal_indices[episode])
        key = rod.goal_set[goal_index].tobytes()
        if repeatable and key in seen:
            traces.append(seen[key])
        elif fork:
            if not settled:
                env.reset(options={"reinitialize": True, "goal_index": goal_index})
                settled = True

            def episode_in_a_copy(goal_index=goal_index):
                obs, info = rod.set_goal(goal_index)
                _, distances, _ = _play(actor, env, obs, max_steps)
                return EpisodeTrace(float(info["distance"]), tuple(distances))

            traces.append(run_in_fork(episode_in_a_copy))
            seen[key] = traces[-1]
        else:
            # The first episode of a chain starts from the initial configuration.
            obs, info = env.reset(options={"reinitialize": reinitialize or i == 0,
                                           "goal_index": goal_index})
            _, distances, _ = _play(actor, env, obs, max_steps)
            traces.append(EpisodeTrace(float(info["distance"]), tuple(distances)))
            if repeatable:
                seen[key] = traces[-1]
        if progress is not None:
            progress()
    return traces


def _layers(env):
    """``env`` and every environment it wraps, outermost first."""
    while True:
        yield env
        if not isinstance(env, gymnasium.Wrapper):
            return
        env = env.env


def _random_episodes(env) -> bool:
    """True if some layer of ``env`` says its episodes are random even from the same goal
    (``random_episodes``: :attr:`dlo_course.env.DLOShapeEnv.random_episodes`)."""
    return any(getattr(layer, "random_episodes", False) for layer in _layers(env))


def _rewrites_observations(env) -> bool:
    return any(isinstance(layer, gymnasium.ObservationWrapper) for layer in _layers(env))


def run_episodes(actor, env, episode_ids: Sequence[int], goal_indices: np.ndarray,
                 reinitialize: bool, max_steps: int, progress=None) -> list[EpisodeRecord]:
    """:func:`run_traces`, scored at the environment's threshold."""
    traces = run_traces(actor, env, episode_ids, goal_indices, reinitialize, max_steps, progress)
    threshold = env.unwrapped.threshold
    return [trace.record(int(episode), int(goal_indices[episode]), threshold)
            for episode, trace in zip(episode_ids, traces)]


def evaluate(agent: str | Path, goals: str | Path | np.ndarray = "small",
             threshold: float = TRAIN_THRESHOLD, reinitialize: bool = True, episodes: int = 1000,
             max_steps: int = 30, seed: int = 0, n_nodes: int | None = None,
             time_mode: str = "code", show_progress: bool = True) -> tuple[Summary | None, list]:
    """Table I's protocol for one trained agent (:func:`load_actor`) and setting; runs on
    every MPI rank.

    Episodes are split over the ranks (see the module docstring); rank 0 gathers them.

    Returns:
        (summary, records) on rank 0, sorted by episode; (None, []) on the other ranks.
    """
    return evaluate_thresholds(agent, goals, (threshold,), reinitialize, episodes,
                               max_steps, seed, n_nodes, time_mode, show_progress)[threshold]


def evaluate_thresholds(agent: str | Path | Controller, goals: str | Path | np.ndarray,
                        thresholds: Sequence[float], reinitialize: bool = True,
                        episodes: int = 1000, max_steps: int = 30, seed: int = 0,
                        n_nodes: int | None = None, time_mode: str = "code",
                        show_progress: bool = True, env_kwargs: dict | None = None,
                        env_wrapper=None) -> dict[float, tuple[Summary | None, list]]:
    """:func:`evaluate` at several thresholds, with the same goals.

    ``agent`` may also be a :class:`Controller` (a hand-made policy), evaluated the same way.

    ``env_kwargs`` (e.g. ``{"params": SimParams(...)}``) go to every test environment, and
    ``env_wrapper``, a callable, wraps each one (e.g. observation noise): how
    :func:`dlo_course.robustness.evaluate_perturbed` tests an agent in a perturbed world.

    With reinitialisation the episodes are run once, at the smallest threshold, and scored at
    every threshold (:class:`EpisodeTrace`); without, each threshold has its own chain of
    episodes, since where one episode stops is where the next starts.

    Returns:
        {threshold: (summary, records)} as :func:`evaluate` gives them.
    """
    from dlo_course.env import make_env  # imports PyBullet: only when needed

    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be at least 1, got {max_steps}")
    if not thresholds:
        raise ValueError("give at least one threshold")
    if isinstance(agent, Controller):
        if n_nodes is not None and n_nodes != agent.n_nodes:
            raise ValueError(f"the controller is for {agent.n_nodes} nodes, not {n_nodes}")
        actor, n_nodes = agent, agent.n_nodes
    else:
        actor, n_nodes = load_actor(agent, n_nodes)
    goal_set = resolve_goals(goals, n_nodes)
    schedule = goal_schedule(len(goal_set), episodes, seed)
    rank, size = mpi.rank(), mpi.size()
    mine = list(range(rank, episodes, size))
    runs = [min(thresholds)] if reinitialize else list(thresholds)

    results: dict[float, tuple[Summary | None, list]] = {}
    bar = tqdm(total=len(mine) * len(runs), desc=f"evaluating (rank 0 of {size})",
               unit="episode", disable=not (show_progress and rank == 0))
    try:
        for run_threshold in runs:
            # No TimeLimit: run_traces stops every episode after max_steps itself.
            env = make_env(max_episode_steps=None, n_nodes=n_nodes, goals=goal_set,
                           threshold=run_threshold, time_mode=time_mode,
                           **(env_kwargs or {}))
            if env_wrapper is not None:
                env = env_wrapper(env)
            if isinstance(actor, Controller):
                actor.bind(env)
            try:
                traces = run_traces(actor, env, mine, schedule, reinitialize, max_steps,
                                    progress=lambda: bar.update(1))
            finally:
                env.close()
            scored = thresholds if reinitialize else [run_threshold]
            for threshold in scored:
                records = [trace.record(episode, int(schedule[episode]), threshold)
                           for episode, trace in zip(mine, traces)]
                gathered = mpi.gather(records)
                if rank != 0:
                    results[threshold] = (None, [])
                    continue
                everything = sorted((r for part in gathered for r in part),
                                    key=lambda r: r.episode)
                results[threshold] = (summarize(everything), everything)
    finally:
        bar.close()
    return results
