"""The training loop: many DDPG agents learning one policy together, as in the paper.

Run it as one process, or as N MPI processes (``mpiexec -n N dlo-course train ...``). Each
MPI rank is one agent with its own environment, seed, goals, replay buffer and exploration
noise; all ranks share the networks by starting from rank 0's weights and applying the same
all-reduced gradient at every update (see :mod:`dlo_course.mpi`).

One episode of one agent:

    reset the environment (a new goal; the world rebuilt, or the rod's shape kept if
        reset_between_episodes is False) and the OU noise
    repeat at most steps_per_episode times:
        act with the actor + noise, step the environment, store the transition
        when this agent's episode ends: store its hindsight copies (if her_k > 0)
        once every agent's buffer holds a batch: updates_per_step DDPG updates
            (gradients all-reduced)
        stop when the episode ends (truncated by the step limit, or the goal reached if
            stop_at_goal) for *every* agent

An agent whose episode ended early keeps making updates (from its own buffer) until the
slowest agent is done: an all-reduce is collective, so if one rank skipped an update the
others would wait for it forever.

Rank 0 writes the run directory ``out_dir`` (its files: :mod:`dlo_course.rundir`):
``config.json``, ``progress.csv`` (one row per episode, all agents together), ``actor.pt``
and ``critic.pt`` (the latest networks); every ``checkpoint_every`` episodes the resume
state under ``checkpoints/``, so that ``train(config, resume=True)`` continues a killed run
and gives the same result as a run that was never interrupted; and with ``validate_every``
> 0, ``validation.csv`` and ``best_actor.pt`` with ``best.json``, the actor that did best on
the validation goals so far (:func:`validate`).

Why validate: an agent's test success is not monotonic in training time (our first 4-node
recipe run reached 29 of 30 test goals after 60 episodes and 87 of 100 after 300), and the
training reward says little about it, since the exploration noise and the hindsight goals
blur it. The validation goals are drawn from the training goals *minus* the paper's test
goals, so choosing the best actor on them does not peek at the test.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import gymnasium
import numpy as np
import torch
from tqdm.auto import tqdm

from dlo_course import mpi, rundir
from dlo_course.config import TrainConfig
from dlo_course.database import load_database
from dlo_course.ddpg import DDPG, UpdateRules
from dlo_course.evaluation import run_traces
from dlo_course.her import HindsightRelabeller
from dlo_course.noise import OUNoise
from dlo_course.replay_buffer import ReplayBuffer
from dlo_course.rundir import VALIDATION_COLUMNS, format_cell


# --- one episode of one agent ---


def _episode_seed(agent_seed: int, episode: int) -> int:
    # Reseeding every reset from (agent, episode) makes the goals of a resumed run the same as
    # an uninterrupted run's without saving the simulator's random state.
    return int(np.random.SeedSequence([agent_seed, episode]).generate_state(1)[0])


def reset_options(env: gymnasium.Env, config: TrainConfig) -> dict[str, Any] | None:
    """The ``options`` of a training episode's ``env.reset``: ``None`` (rebuild the world, the
    environment's default) or, with ``reset_between_episodes=False``, keep the rod's shape.

    Raises ``ValueError`` if the shape should be kept but the environment is not the rod's,
    whose reset alone knows the ``reinitialize`` option."""
    if config.reset_between_episodes:
        return None
    from dlo_course.env import DLOShapeEnv  # imports PyBullet: only when needed

    if not isinstance(env.unwrapped, DLOShapeEnv):
        raise ValueError(f"reset_between_episodes=False (keep the shape between episodes) "
                         f"needs DLOShape-v0, whose reset can keep the rod's shape; "
                         f"{config.env_id} cannot")
    return {"reinitialize": False}


def _add_hindsight_copies(buffer: ReplayBuffer, relabeller: HindsightRelabeller,
                          episode: list[tuple[np.ndarray, np.ndarray, float, np.ndarray]]
                          ) -> None:
    """Store the relabelled copies of an episode's (obs, action, reward, next_obs) list."""
    if not episode:
        return
    obs, act, rew, next_obs = (np.asarray(column) for column in zip(*episode))
    copies = relabeller.episode_copies(obs, act, rew, next_obs)
    for i in range(len(copies["rew"])):
        buffer.add(copies["obs"][i], copies["act"][i], copies["rew"][i],
                   copies["next_obs"][i], copies["done"][i])


def run_episode(env: gymnasium.Env, agent: DDPG, buffer: ReplayBuffer, noise: OUNoise,
                config: TrainConfig, seed: int, grad_reducer: Any,
                relabeller: HindsightRelabeller | None = None) -> dict[str, float]:
    """Play one training episode, updating the networks on the way.

    Every rank calls this in step with the others (see the module docstring). With a
    ``relabeller`` (``config.her_k`` > 0), the episode's transitions are also stored again
    with hindsight goals as soon as this agent's episode is over.

    Returns:
        This agent's ``reward`` (sum over the episode), ``length``, final ``distance`` and
        ``success`` (NaN if the environment does not report them), number of ``updates``
        and the mean ``critic_loss``, ``policy_loss``, ``q_mean`` over its updates.
    """
    if config.her_k > 0 and relabeller is None:
        raise ValueError("her_k > 0 needs a HindsightRelabeller (see train)")
    warmup = config.warmup or config.ddpg.batch_size
    obs, info = env.reset(seed=seed, options=reset_options(env, config))
    noise.reset()
    total_reward, length, running, reached = 0.0, 0, True, False
    stats: list[dict[str, float]] = []
    episode = []  # (obs, action, reward, next_obs) of each step, for hindsight relabelling
    for _ in range(config.steps_per_episode):
        if running:
            action = agent.act(obs, noise)
            next_obs, reward, terminated, truncated, info = env.step(action)
            # done = terminated only: a time limit is not a terminal state (see ReplayBuffer.add).
            buffer.add(obs, action, reward, next_obs, terminated)
            # A step where the simulation blew up repeats the last sane observation: it shows
            # no shape the rod reached, so it is not relabelled.
            if relabeller is not None and not info.get("simulation_unstable", False):
                episode.append((obs, action, reward, next_obs))
            obs = next_obs
            total_reward += float(reward)
            length += 1
            reached = reached or bool(info.get("is_success", False))
            running = not (truncated or (terminated and config.stop_at_goal))
            if not running and relabeller is not None:
                _add_hindsight_copies(buffer, relabeller, episode)
        # Learn once every agent holds a batch; decided together because updates are collective.
        if mpi.allreduce_scalars(len(buffer), "min")[0] >= warmup:
            for _ in range(config.updates_per_step):
                stats.append(agent.update(buffer.sample(config.ddpg.batch_size), grad_reducer))
        if mpi.allreduce_scalars(float(running), "max")[0] == 0.0:
            break  # every agent's episode is over
    if running and relabeller is not None:  # cut by steps_per_episode, not by the environment
        _add_hindsight_copies(buffer, relabeller, episode)

    def mean_of(key: str) -> float:
        # policy_loss is missing from the updates that skipped the actor (policy_delay > 1)
        values = [s[key] for s in stats if key in s]
        return float(np.mean(values)) if values else math.nan

    return {
        "reward": total_reward,
        "length": float(length),
        "distance": float(info.get("distance", math.nan)),
        # reached at some step: with stop_at_goal=False the episode runs on past the goal
        "success": float(reached) if "is_success" in info else math.nan,
        "updates": float(len(stats)),
        "critic_loss": mean_of("critic_loss"),
        "policy_loss": mean_of("policy_loss"),
        "q_mean": mean_of("q_mean"),
    }


class _EpisodeRecorder:
    """The replay buffer as an episode function (lesson 09's ``play_episode``) sees it: each
    transition it adds is stored, and kept for this episode's hindsight copies."""

    def __init__(self, buffer: ReplayBuffer, keep: bool) -> None:
        self.buffer, self.keep = buffer, keep
        self.episode: list[tuple[np.ndarray, np.ndarray, float, np.ndarray]] = []

    def add(self, obs, act, rew, next_obs, done) -> None:
        self.buffer.add(obs, act, rew, next_obs, done)
        if self.keep:
            self.episode.append((np.array(obs), np.array(act), float(rew), np.array(next_obs)))

    def __len__(self) -> int:
        return len(self.buffer)

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        return self.buffer.sample(batch_size)


class _ResetWith(gymnasium.Wrapper):
    """``env`` whose ``reset`` passes the training episode's options (keep the rod's shape,
    :func:`reset_options`) to an episode function that calls ``env.reset(seed=...)`` only."""

    def __init__(self, env: gymnasium.Env, options: dict[str, Any] | None) -> None:
        super().__init__(env)
        self._options = options

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        return self.env.reset(seed=seed, options=self._options if options is None else options)


def run_episode_with(play_episode: Callable[..., dict], env: gymnasium.Env, agent: DDPG,
                     buffer: ReplayBuffer, noise: OUNoise, config: TrainConfig, seed: int,
                     relabeller: HindsightRelabeller | None = None) -> dict[str, float]:
    """One agent's training episode played by ``play_episode``, a function with the signature
    of lesson 09's exercise (``env, policy, buffer, max_steps, seed, update, batch_size,
    updates_per_step, warmup`` -> dict with ``reward``, ``length``, ``distance``, ``success``,
    ``updates``): the student's, so that their own episode trains the rod's agent.

    The library supplies the rest, as :func:`run_episode` does: the policy (the actor plus OU
    noise, reset here), the update (the agent's, one agent: no gradient reduction), the
    reset options (through a wrapper of ``env``) and, after the episode, the hindsight
    copies of what ``play_episode`` stored. The episode ends at the goal, as the exercise's
    does, so ``config.stop_at_goal`` must be True (:func:`train` checks). With ``her_k = 0``
    and one agent the run is the one :func:`run_episode` gives, bit for bit
    (``tests/test_trainer.py``); with ``her_k > 0`` the copies are stored after the
    episode's last updates instead of before them, and transitions of a simulation blow-up
    are relabelled too (the function does not see ``info``).

    Returns:
        As :func:`run_episode`; ``critic_loss``, ``policy_loss`` and ``q_mean`` are the means
        over the updates that ``play_episode`` made.
    """
    noise.reset()
    recorder = _EpisodeRecorder(buffer, keep=relabeller is not None)
    stats: list[dict[str, float]] = []

    def update(batch: dict[str, np.ndarray]) -> dict[str, float]:
        stats.append(agent.update(batch))
        return stats[-1]

    result = play_episode(_ResetWith(env, reset_options(env, config)),
                          lambda obs: agent.act(obs, noise), recorder, config.steps_per_episode,
                          seed, update=update, batch_size=config.ddpg.batch_size,
                          updates_per_step=config.updates_per_step, warmup=config.warmup)
    if relabeller is not None:
        _add_hindsight_copies(buffer, relabeller, recorder.episode)
    missing = {"reward", "length", "distance", "success", "updates"} - set(result)
    if missing:
        raise ValueError(f"play_episode returned no {sorted(missing)}")
    if int(result["updates"]) != len(stats):
        raise ValueError(f"play_episode says it made {result['updates']} updates; "
                         f"it called update {len(stats)} times")

    def mean_of(key: str) -> float:
        values = [s[key] for s in stats if key in s]
        return float(np.mean(values)) if values else math.nan

    return {"reward": float(result["reward"]), "length": float(result["length"]),
            "distance": float(result["distance"]), "success": float(result["success"]),
            "updates": float(len(stats)), "critic_loss": mean_of("critic_loss"),
            "policy_loss": mean_of("policy_loss"), "q_mean": mean_of("q_mean")}


# --- validation: choosing the best actor on held-out goals ---


def validation_indices(env: gymnasium.Env, config: TrainConfig) -> np.ndarray:
    """(config.validation_goals,) indices into the environment's goal set, drawn once from
    the run's seed, among the goals that are not the paper's test goals.

    The paper's test goals are records of the training database (Table I tested on goals the
    agents had trained towards), so they are removed here: an actor chosen on them would be
    chosen on the test. Other goal sources have no test goals and give plain draws.
    """
    goal_count = len(env.unwrapped.goal_set)
    allowed = np.arange(goal_count)
    source = config.env_kwargs.get("goals", "small")
    if isinstance(source, str):
        try:
            test = load_database(source).test_indices(env.unwrapped.n_nodes)
            allowed = np.setdiff1d(allowed, test)
        except (ValueError, FileNotFoundError):
            pass  # not an authors'-sweep database: no test goals to hold out
    if config.validation_goals > len(allowed):
        raise ValueError(f"validation_goals={config.validation_goals} but only {len(allowed)} "
                         "goals are not test goals")
    rng = np.random.default_rng([config.seed, 7])
    return np.sort(rng.choice(allowed, size=config.validation_goals, replace=False))


def validate(env: gymnasium.Env, actor: torch.nn.Module, goal_indices: np.ndarray,
             max_steps: int) -> tuple[float, float]:
    """Table I's protocol (with reinitialisation, no noise) on ``goal_indices``, the goals
    shared out over the MPI ranks; every rank must call it and gets the same result.

    Args:
        env: a ``DLOShape-v0`` environment (the training one: its goal set holds the goals).
        actor: the deterministic policy, (1, obs_dim) -> (1, 3).
        goal_indices: (V,) goal indices, the same on every rank.
        max_steps: at most this many actions per episode.

    Returns:
        (done rate, mean final distance in metres) over the V goals.
    """
    threshold = env.unwrapped.threshold
    mine = list(range(mpi.rank(), len(goal_indices), mpi.size()))
    traces = run_traces(actor, env, mine, goal_indices, reinitialize=True, max_steps=max_steps)
    outcomes = [(r.done, r.final_distance) for r in
                (trace.record(i, int(goal_indices[i]), threshold)
                 for i, trace in zip(mine, traces))]
    everything = [o for part in mpi.allgather(outcomes) for o in part]
    return (float(np.mean([done for done, _ in everything])),
            float(np.mean([distance for _, distance in everything])))


def _is_better(done_rate: float, distance: float, counters: dict[str, Any]) -> bool:
    """More goals reached wins; among equals, the closer final shapes."""
    best = counters.get("best_done_rate")
    if best is None:
        return True
    return (done_rate, -distance) > (best, -counters["best_distance"])


def _nanmean(values: list[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


def progress_row(episode: int, counters: dict[str, Any], per_agent: list[dict[str, float]]
                 ) -> dict[str, float]:
    """The ``progress.csv`` row of one episode, from the list of every agent's episode stats."""
    rewards = [a["reward"] for a in per_agent]
    return {
        "episode": episode,
        "transitions": counters["transitions"],
        "updates": counters["updates"],
        "wall_time": counters["elapsed"],
        "reward_mean": float(np.mean(rewards)),
        "reward_min": float(np.min(rewards)),
        "reward_max": float(np.max(rewards)),
        "length_mean": float(np.mean([a["length"] for a in per_agent])),
        **{key: _nanmean([a[src] for a in per_agent]) for key, src in [
            ("distance_mean", "distance"), ("success_rate", "success"),
            ("critic_loss", "critic_loss"), ("policy_loss", "policy_loss"),
            ("q_mean", "q_mean")]},
    }


# --- loggers: where else the per-episode scalars go ---


class TrainingLogger:
    """A hook that receives, on rank 0, the rows the trainer writes to ``progress.csv`` and
    ``validation.csv``, for another destination (TensorBoard, a notebook's live plot...).

    It only reads the rows: whatever it does, the training computes the same numbers."""

    def open(self, run_dir: Path, episodes_done: int) -> None:
        """The run starts in ``run_dir`` after ``episodes_done`` episodes (0 unless resumed;
        rows of later episodes a killed run logged will be logged again)."""

    def episode(self, row: dict[str, float]) -> None:
        """One ``progress.csv`` row (:func:`progress_row`)."""

    def validation(self, row: dict[str, float]) -> None:
        """One ``validation.csv`` row."""

    def close(self) -> None:
        """The run has stopped (finished, failed or interrupted)."""


TENSORBOARD_DIR = "tensorboard"
"""The folder of TensorBoard's event files in a run directory."""


class TensorBoardLogger(TrainingLogger):
    """The per-episode scalars as ``train/COLUMN`` and the validation's as
    ``validation/COLUMN``, with the episode as step, in ``RUN/tensorboard``
    (``tensorboard --logdir RUN``). Needs the ``tensorboard`` package, checked at once."""

    def __init__(self) -> None:
        try:
            from torch.utils.tensorboard import SummaryWriter
        except ImportError as err:  # torch's message names the missing package
            raise ImportError("TensorBoard logging needs the tensorboard package: pip install "
                              "-e '.[tensorboard]' (or pip install tensorboard)") from err
        self._writer_class = SummaryWriter
        self._writer = None

    def open(self, run_dir: Path, episodes_done: int) -> None:
        # purge_step drops what a killed run wrote after its resume state, as progress.csv does
        self._writer = self._writer_class(
            log_dir=str(Path(run_dir) / TENSORBOARD_DIR),
            purge_step=episodes_done + 1 if episodes_done else None)

    def _scalars(self, prefix: str, row: dict[str, float]) -> None:
        step = int(row["episode"])
        for key, value in row.items():
            if key != "episode" and not math.isnan(value):  # NaN: nothing to report
                self._writer.add_scalar(f"{prefix}/{key}", value, global_step=step)

    def episode(self, row: dict[str, float]) -> None:
        self._scalars("train", row)

    def validation(self, row: dict[str, float]) -> None:
        self._scalars("validation", row)
        self._writer.flush()  # rare and worth seeing at once

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


# --- the run ---


def make_env(config: TrainConfig) -> gymnasium.Env:
    """``gymnasium.make`` the configured environment, checking it suits DDPG."""
    try:
        env = gymnasium.make(config.env_id, max_episode_steps=config.steps_per_episode,
                             **config.env_kwargs)
    except (gymnasium.error.Error, TypeError) as err:  # unknown id, or wrong env_kwargs
        raise ValueError(f"cannot make environment {config.env_id!r}: {err}") from err
    for name, space in (("observation", env.observation_space), ("action", env.action_space)):
        if not (isinstance(space, gymnasium.spaces.Box) and len(space.shape) == 1):
            env.close()
            raise ValueError(f"DDPG needs a 1-D Box {name} space; {config.env_id} has {space}")
    return env


def observation_reference(env: gymnasium.Env) -> tuple[np.ndarray, np.ndarray]:
    """(offset, scale) for ``dlo_course.config.DDPGConfig.normalize_obs``: the environment's own
    ``observation_reference()`` if it has one (the rod), else the centre and half-width of a
    bounded observation space."""
    if hasattr(env.unwrapped, "observation_reference"):
        return env.unwrapped.observation_reference()
    low, high = env.observation_space.low, env.observation_space.high
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise ValueError("normalize_obs needs an environment with observation_reference() "
                         "or a bounded observation space")
    return (low + high) / 2, np.maximum((high - low) / 2, 1e-6)


def train(config: TrainConfig, resume: bool = False, progress: bool = True,
          overwrite: bool = False, rules: UpdateRules | None = None,
          loggers: Sequence[TrainingLogger] = (),
          play_episode: Callable[..., dict] | None = None) -> Path:
    """Train DDPG agents as configured; every MPI rank runs this function as one agent.

    Args:
        config: the run's configuration (see :data:`dlo_course.config.PRESETS`).
        resume: continue from the resume state in ``config.out_dir`` (start afresh if
            there is none). ``episodes`` may be raised to train a finished run further.
        progress: show a progress bar (rank 0 only).
        overwrite: allow starting a new run in a directory that already holds one.
        rules: the DDPG update's formulas (:class:`~dlo_course.ddpg.UpdateRules`; the paper's
            by default). Not part of the configuration: functions cannot be saved in
            ``config.json``, so a run trained with other rules records only its settings.
        loggers: hooks that also get every ``progress.csv`` and ``validation.csv`` row
            (:class:`TrainingLogger`; e.g. :class:`TensorBoardLogger`), on rank 0.
        play_episode: who plays each episode: ``None``, the library (:func:`run_episode`),
            or a function with the signature of lesson 09's exercise
            (:func:`run_episode_with`): one agent only (it makes no collective update),
            episodes that end at the goal (``config.stop_at_goal``). Like ``rules``, not
            saved in ``config.json``.

    Returns:
        The run directory.
    """
    torch.set_num_threads(config.torch_threads)
    out = Path(config.out_dir)
    n_agents, root = mpi.size(), mpi.is_root()
    if not resume and not overwrite and (out / rundir.PROGRESS_FILE).exists():
        # Every rank sees the same files, so every rank raises: nobody is left waiting.
        raise FileExistsError(f"{out} already holds a run: resume it (--resume) or choose "
                              "another directory (--out), or pass --overwrite")
    if play_episode is not None and (n_agents > 1 or not config.stop_at_goal):
        raise ValueError("an episode function (play_episode) trains one agent, whose episodes "
                         f"end at the goal: run it without mpiexec (here {n_agents} agents) "
                         f"and with stop_at_goal=True (here {config.stop_at_goal})")
    if root and config.expected_agents and n_agents != config.expected_agents:
        print(f"warning: this configuration is meant for {config.expected_agents} agents "
              f"(mpiexec -n {config.expected_agents}); running with {n_agents}",
              file=sys.stderr)

    agent_seed = mpi.rank_seed(config.seed, mpi.rank())
    torch.manual_seed(agent_seed)  # network initialisation (rank 0's wins, see below)
    env = make_env(config)
    try:  # options that need a particular environment: fail now, not after an episode
        reset_options(env, config)
        relabeller = (HindsightRelabeller.for_env(env, config.her_k, seed=agent_seed + 2)
                      if config.her_k > 0 else None)
    except ValueError:
        env.close()
        raise
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    obs_offset, obs_scale = (observation_reference(env) if config.ddpg.normalize_obs
                             else (None, None))
    agent = DDPG(obs_dim, act_dim, env.action_space.low, env.action_space.high, config.ddpg,
                 obs_offset, obs_scale, rules)
    # default_rng hashes its seed, so the neighbouring seeds give unrelated streams.
    buffer = ReplayBuffer(obs_dim, act_dim, config.ddpg.buffer_size, seed=agent_seed)
    noise = OUNoise(act_dim, config.ddpg.noise_theta, config.ddpg.noise_sigma,
                    config.ddpg.noise_mu, seed=agent_seed + 1)
    # All agents start from rank 0's networks; the targets are copies of them.
    mpi.broadcast_module(agent.actor)
    for critic in agent.critics:
        mpi.broadcast_module(critic)
    agent.sync_targets()

    counters = {"episodes_done": 0, "transitions": 0, "updates": 0, "elapsed": 0.0}
    if resume:
        loaded = rundir.load_resume_state(out, agent, buffer, noise, relabeller, config)
        if loaded is not None:
            counters = loaded
        elif root:
            print(f"no resume state in {out}: starting from scratch", file=sys.stderr)
    elif root:
        rundir.delete_resume_state(out)  # overwrite: a stale resume state must not be resumed

    checks = validation_indices(env, config) if config.validate_every else None
    progress_file = validation_file = None
    if root:
        out.mkdir(parents=True, exist_ok=True)
        rundir.write_config(out, config, n_agents)
        progress_file, writer = rundir.open_episode_log(out / rundir.PROGRESS_FILE,
                                                        counters["episodes_done"])
        if checks is not None:
            validation_file, validation_writer = rundir.open_episode_log(
                out / rundir.VALIDATION_FILE, counters["episodes_done"], VALIDATION_COLUMNS)
        for logger in loggers:
            logger.open(out, counters["episodes_done"])

    reducer = (functools.partial(mpi.allreduce_gradients, op=config.reduce)
               if n_agents > 1 else None)
    bar = tqdm(total=config.episodes, initial=counters["episodes_done"], unit="episode",
               disable=not (progress and root), dynamic_ncols=True)
    start = time.perf_counter() - counters["elapsed"]
    try:
        for episode in range(counters["episodes_done"], config.episodes):
            seed = _episode_seed(agent_seed, episode)
            if play_episode is None:
                mine = run_episode(env, agent, buffer, noise, config, seed, reducer, relabeller)
            else:
                mine = run_episode_with(play_episode, env, agent, buffer, noise, config, seed,
                                        relabeller)
            per_agent = mpi.allgather(mine)  # every agent's stats, on every rank
            counters["episodes_done"] = episode + 1
            counters["updates"] += int(mine["updates"])  # identical on every rank
            counters["transitions"] += int(sum(a["length"] for a in per_agent))
            counters["elapsed"] = time.perf_counter() - start
            if root:
                row = progress_row(episode + 1, counters, per_agent)
                writer.writerow({k: format_cell(v) for k, v in row.items()})
                progress_file.flush()
                for logger in loggers:
                    logger.episode(row)
                bar.set_postfix(reward=f"{row['reward_mean']:.3g}")
                bar.update(1)
            if checks is not None and (episode + 1) % config.validate_every == 0:
                began = time.perf_counter()
                done_rate, distance = validate(env, agent.actor, checks, config.validation_steps)
                better = _is_better(done_rate, distance, counters)
                if better:  # the same decision on every rank: the results were all-gathered
                    counters.update(best_done_rate=done_rate, best_distance=distance,
                                    best_episode=episode + 1,
                                    best_transitions=counters["transitions"])
                if root:
                    rundir.save_validated_actor(out, agent.actor, episode + 1)
                    if better:
                        rundir.save_best_actor(out, agent.actor, counters)
                    checked = {"episode": episode + 1, "transitions": counters["transitions"],
                               "done_rate": done_rate, "distance_mean": distance,
                               "best": int(better), "seconds": time.perf_counter() - began}
                    validation_writer.writerow({k: format_cell(v) for k, v in checked.items()})
                    validation_file.flush()
                    for logger in loggers:
                        logger.validation(checked)
                    bar.set_postfix(reward=f"{row['reward_mean']:.3g}",
                                    validation=f"{done_rate:.0%}")
            if (episode + 1) % config.checkpoint_every == 0 or episode + 1 == config.episodes:
                if not mpi.modules_in_sync(agent.actor, *agent.critics):
                    raise RuntimeError("the agents' networks have diverged: the MPI "
                                       "reduction did not give every rank the same bits")
                rundir.save_resume_state(out, agent, buffer, noise, relabeller, counters, config)
    finally:
        bar.close()
        env.close()
        for f in (progress_file, validation_file):
            if f is not None:
                f.close()
        if root:
            for logger in loggers:
                logger.close()
    return out
