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
        stop when the episode ends (terminated or truncated) for *every* agent

An agent whose episode ended early keeps making updates (from its own buffer) until the
slowest agent is done: an all-reduce is collective, so if one rank skipped an update the
others would wait for it forever.

Rank 0 writes, in ``out_dir``:

* ``config.json``: the configuration, number of agents and library versions;
* ``progress.csv``: one row per episode (all agents together; see :data:`PROGRESS_COLUMNS`);
* ``actor.pt``, ``critic.pt``: the latest networks (:func:`dlo_course.ddpg.load_network`;
  with twin critics, ``critic.pt`` is the first one);
* ``checkpoints/``: every ``checkpoint_every`` episodes, the full state of the run, so that
  ``train(config, resume=True)`` continues a killed run and gives the same result as a run
  that was never interrupted;
* with ``validate_every`` > 0: ``validation.csv`` (one row per validation, see
  :data:`VALIDATION_COLUMNS`), and ``best_actor.pt`` with ``best.json``, the actor that did
  best on the validation goals so far (:func:`validate`).

Why validate: an agent's test success is not monotonic in training time (our first 4-node
recipe run reached 29 of 30 test goals after 60 episodes and 87 of 100 after 300), and the
training reward says little about it, since the exploration noise and the hindsight goals
blur it. The validation goals are drawn from the training goals *minus* the paper's test
goals, so choosing the best actor on them does not peek at the test.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import functools
import json
import math
import os
import platform
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from tqdm.auto import tqdm

from dlo_course import mpi
from dlo_course.ddpg import DDPG, DDPGConfig, UpdateRules, save_network
from dlo_course.her import HindsightRelabeller
from dlo_course.noise import OUNoise
from dlo_course.replay_buffer import ReplayBuffer


@dataclass
class TrainConfig:
    """Everything that defines a training run. Defaults follow the paper, for 2 rod nodes."""

    env_id: str = "DLOShape-v0"
    """Gymnasium id of the environment; any continuous-control (Box) environment works."""
    env_kwargs: dict[str, Any] = field(default_factory=lambda: {"n_nodes": 2})
    """Keyword arguments of ``gymnasium.make`` (for the rod: ``n_nodes`` = 2, 4 or 6)."""
    episodes: int = 63
    """Episodes per agent (the paper: 63, i.e. 32 x 63 = 2016 episodes in all)."""
    steps_per_episode: int = 300
    """Maximum actions per episode; also passed as ``max_episode_steps`` to the environment."""
    seed: int = 0
    """Run seed; each agent's seed is derived from it and its rank (:func:`mpi.rank_seed`)."""
    out_dir: str = "runs/train"
    """Directory of the run's files."""
    checkpoint_every: int = 10
    """Save the full training state every this many episodes (and after the last one)."""
    reduce: str = "sum"
    """How gradients are combined over agents: ``"sum"`` (the paper) or ``"mean"``."""
    warmup: int | None = None
    """Updates start once every agent's buffer holds this many transitions
    (``None``: one batch, as in the paper and the authors' code)."""
    expected_agents: int | None = None
    """Number of MPI ranks the preset is meant for; a different number only gives a warning."""
    updates_per_step: int = 1
    """DDPG updates per environment step (the paper and the authors' code: 1). More reuse
    each costly simulator transition; an update costs a few ms, a rod step ~110 ms."""
    her_k: int = 0
    """Hindsight relabelling (HER, "future" strategy; :mod:`dlo_course.her`): at the end of
    each episode, store every transition again this many times, each time with a goal the
    rod reached later in that episode (0: off, as in the paper; the HER paper: 4). Needs a
    goal-reaching environment such as ``DLOShape-v0``. A trainer option rather than a DDPG
    one: it changes what is stored, and only the trainer knows episodes and the environment's
    observation layout and threshold; the DDPG update never sees the difference."""
    reset_between_episodes: bool = True
    """True: rebuild the world before every training episode (the paper's text). False: a
    training episode starts from the shape the previous one ended in and only a new goal is
    drawn (the authors' code). The first episode, and any after a simulation blow-up, start
    from a rebuilt world anyway. False needs ``DLOShape-v0``, whose reset can keep the shape."""
    validate_every: int = 0
    """Every this many episodes, run the deterministic actor on ``validation_goals`` held-out
    goals (:func:`validate`) and keep the best actor in ``best_actor.pt`` (0: never, as in
    the paper). Costs about 6 s per goal (a rebuilt world and up to ``validation_steps``
    actions), shared by the ranks."""
    validation_goals: int = 30
    """How many validation goals: drawn once from the run's seed among the training goals
    that are not the paper's test goals (:func:`validation_indices`)."""
    validation_steps: int = 30
    """At most this many actions per validation episode (Table I's 30)."""
    torch_threads: int = 1
    """PyTorch threads per process. One: the ranks already fill the cores, and more threads
    per rank would fight over them."""
    ddpg: DDPGConfig = field(default_factory=DDPGConfig)
    """DDPG hyperparameters (networks, learning rates, buffer, noise)."""

    def __post_init__(self) -> None:
        if isinstance(self.ddpg, dict):  # read back from config.json
            self.ddpg = DDPGConfig(**self.ddpg)
        self.env_kwargs = dict(self.env_kwargs)
        if self.episodes < 1:
            raise ValueError(f"episodes must be at least 1, got {self.episodes}")
        if self.steps_per_episode < 1:
            raise ValueError(f"steps_per_episode must be at least 1, got {self.steps_per_episode}")
        if self.checkpoint_every < 1:
            raise ValueError(f"checkpoint_every must be at least 1, got {self.checkpoint_every}")
        if self.reduce not in ("sum", "mean"):
            raise ValueError(f"reduce must be 'sum' or 'mean', got {self.reduce!r}")
        if self.updates_per_step < 1:
            raise ValueError(f"updates_per_step must be at least 1, got {self.updates_per_step}")
        if self.her_k < 0:
            raise ValueError(f"her_k must be >= 0 (0: no hindsight relabelling), got {self.her_k}")
        if self.validate_every < 0:
            raise ValueError(f"validate_every must be >= 0 (0: no validation), "
                             f"got {self.validate_every}")
        if self.validation_goals < 1 or self.validation_steps < 1:
            raise ValueError("validation_goals and validation_steps must be at least 1, got "
                             f"{self.validation_goals} and {self.validation_steps}")
        if self.warmup is not None and self.warmup < 1:
            raise ValueError(f"warmup must be at least 1, got {self.warmup}")
        if "max_episode_steps" in self.env_kwargs:
            raise ValueError("set steps_per_episode, not env_kwargs['max_episode_steps']")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TrainConfig":
        return cls(**d)


PRESETS: dict[str, TrainConfig] = {
    # Seconds of learning code on top of ~40 simulator steps per agent: for CI and notebooks.
    # The batch is small so that updates do happen within 2 x 20 steps.
    "smoke": TrainConfig(episodes=2, steps_per_episode=20, checkpoint_every=1,
                         out_dir="runs/smoke", ddpg=DDPGConfig(batch_size=16)),
    # About an hour on a 4-core laptop at ~5 simulator actions per second per core.
    "laptop": TrainConfig(episodes=60, steps_per_episode=150, checkpoint_every=5,
                          out_dir="runs/laptop", expected_agents=4),
    # The paper: 32 agents x 63 episodes x 300 steps, gradients summed.
    "paper": TrainConfig(episodes=63, steps_per_episode=300, checkpoint_every=7,
                         out_dir="runs/paper", expected_agents=32, reduce="sum"),
    # What 2 cores can train in about an hour (~16 rod transitions/s): the paper's DDPG with
    # four course options that make a small budget go further (docs/design.md, "Training on
    # two cores"): fixed input scaling, a penalty on the saturated actor, shorter episodes
    # (more goals per transition; test episodes are 30 steps) and 2 updates per step.
    "course": TrainConfig(episodes=240, steps_per_episode=60, checkpoint_every=10,
                          out_dir="runs/course", expected_agents=2, updates_per_step=2,
                          ddpg=DDPGConfig(normalize_obs=True, preactivation_l2=0.01,
                                          noise_sigma=0.15)),
    # PROVISIONAL, a first guess to be tuned by the ablation of issue 12: the course preset's
    # options on the 4-node task, plus every training lever at once (docs/design.md,
    # "Training levers"): hindsight relabelling, TD3's three fixes, episodes that keep the
    # rod's shape (the authors' code), bigger batches and buffer. 30 000 rod transitions per
    # agent: at ~16 transitions/s on 2 cores, about an hour of simulation plus the updates.
    "recipe": TrainConfig(env_kwargs={"n_nodes": 4}, episodes=500, steps_per_episode=60,
                          checkpoint_every=10, out_dir="runs/recipe", expected_agents=2,
                          updates_per_step=2, her_k=4, reset_between_episodes=False,
                          validate_every=20, validation_goals=30,
                          ddpg=DDPGConfig(normalize_obs=True, preactivation_l2=0.01,
                                          noise_sigma=0.15, batch_size=256,
                                          buffer_size=200_000, twin_critics=True,
                                          policy_delay=2, target_noise=0.1,
                                          target_noise_clip=0.3)),
}


def preset(name: str, **overrides: Any) -> TrainConfig:
    """A copy of preset ``name`` (a key of :data:`PRESETS`) with some fields changed."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return dataclasses.replace(copy.deepcopy(PRESETS[name]), **overrides)


def load_config(run_dir: str | Path) -> TrainConfig:
    """The :class:`TrainConfig` of a run, read from its ``config.json``."""
    return TrainConfig.from_dict(json.loads((Path(run_dir) / "config.json").read_text())["config"])


PROGRESS_COLUMNS = [
    "episode",         # 1, 2, ... (each agent has played this many episodes)
    "transitions",     # environment steps so far, all agents together
    "updates",         # gradient updates so far (the same on every agent)
    "wall_time",       # seconds since the run started (only time spent running is counted)
    "reward_mean",     # episode reward (sum over its steps), mean over agents: Fig. 4
    "reward_min",      # ... and its min and max over agents
    "reward_max",
    "length_mean",     # steps per episode, mean over agents
    "distance_mean",   # info["distance"] at the end of the episode, mean over agents (m)
    "success_rate",    # share of agents whose episode ended with info["is_success"]
    "critic_loss",     # mean over the episode's updates and over agents
    "policy_loss",
    "q_mean",
]

VALIDATION_COLUMNS = [
    "episode",         # validated after this many episodes per agent
    "transitions",     # environment steps so far, all agents together
    "done_rate",       # share of the validation goals reached (mean node distance < threshold)
    "distance_mean",   # final mean node distance (m), mean over the validation goals
    "best",            # 1 if this actor became best_actor.pt
    "seconds",         # wall time the validation took
]


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
    total_reward, length, running = 0.0, 0, True
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
            running = not (terminated or truncated)
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
        "success": float(info["is_success"]) if "is_success" in info else math.nan,
        "updates": float(len(stats)),
        "critic_loss": mean_of("critic_loss"),
        "policy_loss": mean_of("policy_loss"),
        "q_mean": mean_of("q_mean"),
    }


# --- validation: choosing the best actor on held-out goals ---


def validation_indices(env: gymnasium.Env, config: TrainConfig) -> np.ndarray:
    """(config.validation_goals,) indices into the environment's goal set, drawn once from
    the run's seed, among the goals that are not the paper's test goals.

    The paper's test goals are records of the training database (Table I tested on goals the
    agents had trained towards), so they are removed here: an actor chosen on them would be
    chosen on the test. Other goal sources have no test goals and give plain draws.
    """
    from dlo_course.database import load_database  # imports nothing heavy, but only if needed

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
    from dlo_course.evaluation import run_traces  # imports PyBullet through the env

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


def _format(value: float) -> str:
    if isinstance(value, int):
        return str(value)
    return "" if math.isnan(value) else format(value, ".8g")


# --- files ---


def _atomic_torch_save(obj: Any, path: Path) -> None:
    # Write then rename: a run killed while saving leaves the previous file intact.
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def _write_json(obj: Any, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2) + "\n")
    os.replace(tmp, path)


def _save_checkpoint(out: Path, agent: DDPG, buffer: ReplayBuffer, noise: OUNoise,
                     relabeller: HindsightRelabeller | None, counters: dict[str, Any],
                     config: TrainConfig) -> None:
    """Every rank saves its own state; rank 0 the shared networks and optimisers. The
    ``latest.json`` pointer moves only once every file is complete."""
    ckpt_root = out / "checkpoints"
    name = f"episode{counters['episodes_done']:06d}"
    ckpt = ckpt_root / name
    if mpi.is_root():
        ckpt.mkdir(parents=True, exist_ok=True)
    mpi.barrier()
    _atomic_torch_save({"buffer": buffer.state_dict(), "noise": noise.state_dict(),
                        "her": None if relabeller is None else relabeller.state_dict(),
                        "torch_rng": torch.get_rng_state()},
                       ckpt / f"state_rank{mpi.rank()}.pt")
    if mpi.is_root():
        _atomic_torch_save({"agent": agent.state_dict(), "counters": dict(counters),
                            "n_agents": mpi.size(), "config": config.to_dict()},
                           ckpt / "shared.pt")
    mpi.barrier()
    if mpi.is_root():
        _write_json({"checkpoint": name, **counters}, ckpt_root / "latest.json")
        for old in ckpt_root.iterdir():
            if old.is_dir() and old.name != name:
                shutil.rmtree(old)
        save_network(agent.actor, out / "actor.pt")
        save_network(agent.critic, out / "critic.pt")


def _save_best(out: Path, agent: DDPG, counters: dict[str, Any]) -> None:
    """Keep the actor that did best on the validation goals, with when and how well."""
    tmp = out / "best_actor.pt.tmp"
    save_network(agent.actor, tmp)
    os.replace(tmp, out / "best_actor.pt")
    _write_json({"episode": counters["best_episode"],
                 "transitions": counters["best_transitions"],
                 "done_rate": counters["best_done_rate"],
                 "distance_mean": counters["best_distance"]}, out / "best.json")


# Fields that may change when a run is resumed (e.g. to train for more episodes).
_RESUMABLE_CHANGES = {"episodes", "out_dir", "checkpoint_every", "expected_agents",
                      "torch_threads", "validate_every"}


def _load_checkpoint(out: Path, agent: DDPG, buffer: ReplayBuffer, noise: OUNoise,
                     relabeller: HindsightRelabeller | None, config: TrainConfig
                     ) -> dict[str, Any] | None:
    """Restore the latest checkpoint of ``out`` into this rank's objects; return the counters,
    or ``None`` if there is no checkpoint."""
    pointer = out / "checkpoints" / "latest.json"
    if not pointer.exists():
        return None
    ckpt = out / "checkpoints" / json.loads(pointer.read_text())["checkpoint"]
    # Our own files, holding NumPy arrays and generator states: not weights_only.
    shared = torch.load(ckpt / "shared.pt", weights_only=False)
    if shared["n_agents"] != mpi.size():
        raise ValueError(f"{out} was trained with {shared['n_agents']} agents; resume it with "
                         f"the same number of MPI ranks (got {mpi.size()})")
    # Through the dataclass, so that an option added since the checkpoint reads as its
    # default (off) instead of as a difference.
    saved, now = TrainConfig.from_dict(shared["config"]).to_dict(), config.to_dict()
    changed = sorted(k for k in now if k not in _RESUMABLE_CHANGES and saved.get(k) != now[k])
    if changed:
        raise ValueError(f"cannot resume {out}: the configuration differs in {changed}")
    mine = torch.load(ckpt / f"state_rank{mpi.rank()}.pt", weights_only=False)
    agent.load_state_dict(shared["agent"])
    buffer.load_state_dict(mine["buffer"])
    noise.load_state_dict(mine["noise"])
    if relabeller is not None:
        relabeller.load_state_dict(mine["her"])
    torch.set_rng_state(mine["torch_rng"])
    return dict(shared["counters"])


def _open_progress(path: Path, keep_episodes: int, columns: list[str] = PROGRESS_COLUMNS
                   ) -> tuple[Any, csv.DictWriter]:
    """Open ``progress.csv`` (or another per-episode CSV with ``columns``) for appending,
    keeping only the rows of the first ``keep_episodes`` episodes (rows written after the last
    checkpoint are replayed). Returns the open file and a CSV writer on it."""
    rows: list[dict[str, str]] = []
    if keep_episodes > 0 and path.exists():
        with path.open(newline="") as f:
            rows = [r for r in csv.DictReader(f) if int(r["episode"]) <= keep_episodes]
    f = path.open("w", newline="")
    writer = csv.DictWriter(f, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    f.flush()
    return f, writer


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


def _git_commit() -> str | None:
    """The commit of the library's source, if it runs from a git checkout (for the record)."""
    import subprocess

    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10, cwd=Path(__file__).parent)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    return out.stdout.strip() or None


def observation_reference(env: gymnasium.Env) -> tuple[np.ndarray, np.ndarray]:
    """(offset, scale) for ``DDPGConfig.normalize_obs``: the environment's own
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
          overwrite: bool = False, rules: UpdateRules | None = None) -> Path:
    """Train DDPG agents as configured; every MPI rank runs this function as one agent.

    Args:
        config: the run's configuration (see :data:`PRESETS`).
        resume: continue from the last checkpoint in ``config.out_dir`` (start afresh if
            there is none). ``episodes`` may be raised to train a finished run further.
        progress: show a progress bar (rank 0 only).
        overwrite: allow starting a new run in a directory that already holds one.
        rules: the DDPG update's formulas (:class:`~dlo_course.ddpg.UpdateRules`; the paper's
            by default). Not part of the configuration: functions cannot be saved in
            ``config.json``, so a run trained with other rules records only its settings.

    Returns:
        The run directory.
    """
    torch.set_num_threads(config.torch_threads)
    out = Path(config.out_dir)
    n_agents, root = mpi.size(), mpi.is_root()
    if not resume and not overwrite and (out / "progress.csv").exists():
        # Every rank sees the same files, so every rank raises: nobody is left waiting.
        raise FileExistsError(f"{out} already holds a run: resume it (--resume) or choose "
                              "another directory (--out), or pass --overwrite")
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
        loaded = _load_checkpoint(out, agent, buffer, noise, relabeller, config)
        if loaded is not None:
            counters = loaded
        elif root:
            print(f"no checkpoint in {out}: starting from scratch", file=sys.stderr)
    elif root and (out / "checkpoints").exists():
        shutil.rmtree(out / "checkpoints")  # overwrite: stale checkpoints must not be resumed

    checks = validation_indices(env, config) if config.validate_every else None
    progress_file = validation_file = None
    if root:
        out.mkdir(parents=True, exist_ok=True)
        _write_json({"config": config.to_dict(), "n_agents": n_agents, "commit": _git_commit(),
                     "versions": {"python": platform.python_version(), "torch": torch.__version__,
                                  "gymnasium": gymnasium.__version__, "numpy": np.__version__}},
                    out / "config.json")
        progress_file, writer = _open_progress(out / "progress.csv", counters["episodes_done"])
        if checks is not None:
            validation_file, validation_writer = _open_progress(
                out / "validation.csv", counters["episodes_done"], VALIDATION_COLUMNS)

    reducer = (functools.partial(mpi.allreduce_gradients, op=config.reduce)
               if n_agents > 1 else None)
    bar = tqdm(total=config.episodes, initial=counters["episodes_done"], unit="episode",
               disable=not (progress and root), dynamic_ncols=True)
    start = time.perf_counter() - counters["elapsed"]
    try:
        for episode in range(counters["episodes_done"], config.episodes):
            mine = run_episode(env, agent, buffer, noise, config,
                               _episode_seed(agent_seed, episode), reducer, relabeller)
            per_agent = mpi.allgather(mine)  # every agent's stats, on every rank
            counters["episodes_done"] = episode + 1
            counters["updates"] += int(mine["updates"])  # identical on every rank
            counters["transitions"] += int(sum(a["length"] for a in per_agent))
            counters["elapsed"] = time.perf_counter() - start
            if root:
                row = progress_row(episode + 1, counters, per_agent)
                writer.writerow({k: _format(v) for k, v in row.items()})
                progress_file.flush()
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
                    if better:
                        _save_best(out, agent, counters)
                    validation_writer.writerow({k: _format(v) for k, v in {
                        "episode": episode + 1, "transitions": counters["transitions"],
                        "done_rate": done_rate, "distance_mean": distance,
                        "best": int(better), "seconds": time.perf_counter() - began}.items()})
                    validation_file.flush()
                    bar.set_postfix(reward=f"{row['reward_mean']:.3g}",
                                    validation=f"{done_rate:.0%}")
            if (episode + 1) % config.checkpoint_every == 0 or episode + 1 == config.episodes:
                if not mpi.modules_in_sync(agent.actor, *agent.critics):
                    raise RuntimeError("the agents' networks have diverged: the MPI "
                                       "reduction did not give every rank the same bits")
                _save_checkpoint(out, agent, buffer, noise, relabeller, counters, config)
    finally:
        bar.close()
        env.close()
        for f in (progress_file, validation_file):
            if f is not None:
                f.close()
    return out
