"""A training run on disk: the names of its files, how they are written and read, the record
of what a training cost, and shipping a run as a trained agent.

Four words, each for one thing, in the code and in its docstrings:

* **run directory**: the folder one training run writes (``TrainConfig.out_dir``):

  ====================== ============================================================
  ``config.json``        the configuration, number of agents, commit, library versions
  ``progress.csv``       one row per episode (:data:`PROGRESS_COLUMNS`)
  ``validation.csv``     one row per validation (:data:`VALIDATION_COLUMNS`), if any
  ``actor.pt``           the actor of the last resume state (an *actor file*)
  ``critic.pt``          its critic (the first one, with twin critics)
  ``best_actor.pt``      the actor that did best on the validation goals, if any
  ``best.json``          when it was saved and how well it did
  ``validated/``         every validated actor, ``actor_epNNNNNN.pt``: a larger validation
                         after training can pick among them (:func:`validated_actors`)
  ``checkpoints/``       the *resume state* (below)
  ====================== ============================================================

* **resume state**: everything needed to continue a killed run as if it had never stopped,
  ``checkpoints/episodeNNNNNN/`` (``shared.pt``: networks, optimisers, counters,
  configuration; ``state_rank{r}.pt``: each agent's replay buffer, noise, relabeller and
  torch generator), and the pointer ``checkpoints/latest.json``, moved only once every file
  of a new resume state is complete. The folder keeps its historical name, ``checkpoints``,
  so that runs written before this module still resume.
* **trained agent**: what :func:`ship_run` copies out of a run directory, without the bulky
  resume state: ``actor.pt``, ``critic.pt``, ``config.json``, ``progress.csv``,
  ``record.json`` (:func:`run_record`), and ``validation.csv`` and ``best.json`` when the run
  validated. The shipped agents live in ``data/checkpoints/nodes{2,4,6}`` (:func:`agent_dir`).
  A run directory is a trained agent too, minus ``record.json``: everything that evaluates
  an agent takes either.
* **actor file**: one saved network, :func:`dlo_course.ddpg.save_network`'s format.

Every file is written through :func:`atomic_write` (write a temporary file, then rename it
over the old one): a run killed while saving leaves the previous version intact.
"""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import shutil
import subprocess
from pathlib import Path
from typing import Any, Callable

import gymnasium
import numpy as np
import torch

from dlo_course import mpi
from dlo_course.config import TrainConfig
from dlo_course.ddpg import save_network

CONFIG_FILE = "config.json"
PROGRESS_FILE = "progress.csv"
VALIDATION_FILE = "validation.csv"
ACTOR_FILE = "actor.pt"
CRITIC_FILE = "critic.pt"
BEST_ACTOR_FILE = "best_actor.pt"
BEST_FILE = "best.json"
VALIDATED_DIR = "validated"
RECORD_FILE = "record.json"
RESUME_DIR = "checkpoints"
"""The resume state's folder inside a run directory (its name predates this module)."""
RESUME_POINTER = "latest.json"
SHARED_STATE_FILE = "shared.pt"

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


class RunFileError(ValueError):
    """A file of a run directory or trained agent is truncated, corrupt, or does not hold
    what it should; the message names the file."""


# --- writing files ---


def atomic_write(path: str | Path, write: Callable[[Path], Any]) -> None:
    """Call ``write(tmp)`` to write a temporary file beside ``path``, then rename it to
    ``path``: readers (and a run killed meanwhile) only ever see a complete file."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    write(tmp)
    os.replace(tmp, path)


def write_json(obj: Any, path: str | Path) -> None:
    """``obj`` as indented JSON, atomically."""
    atomic_write(path, lambda tmp: tmp.write_text(json.dumps(obj, indent=2) + "\n"))


def read_json(path: str | Path) -> Any:
    """A JSON file; :class:`RunFileError` if it is not JSON (a missing file stays a
    ``FileNotFoundError``)."""
    try:
        return json.loads(Path(path).read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise RunFileError(f"{path} is not valid JSON (truncated or corrupt?): {err}") from err


def _config_in(saved: Any, path: Path) -> TrainConfig:
    """The configuration of a ``config.json`` or resume state read from ``path``."""
    try:
        return TrainConfig.from_dict(saved["config"])
    except (KeyError, TypeError, ValueError) as err:
        raise RunFileError(f"{path} does not hold a valid training configuration "
                           f"({type(err).__name__}: {err})") from err


def _torch_save(obj: Any, path: Path) -> None:
    atomic_write(path, lambda tmp: torch.save(obj, tmp))


def _save_network_file(net: torch.nn.Module, path: Path) -> None:
    atomic_write(path, lambda tmp: save_network(net, tmp))


def format_cell(value: float) -> str:
    """A CSV cell of a per-episode log: integers as they are, floats to 8 significant
    digits, NaN (nothing to report) as an empty cell."""
    if isinstance(value, int):
        return str(value)
    return "" if math.isnan(value) else format(value, ".8g")


# --- config.json ---


def git_commit() -> str | None:
    """The commit of the library's source, if it runs from a git checkout (for the record)."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, timeout=10, cwd=Path(__file__).parent)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    return out.stdout.strip() or None


def write_config(run_dir: Path, config: TrainConfig, n_agents: int) -> None:
    """``config.json``: the configuration, the number of agents, the commit and the versions
    of the libraries that decide the numbers."""
    write_json({"config": config.to_dict(), "n_agents": n_agents, "commit": git_commit(),
                "versions": {"python": platform.python_version(), "torch": torch.__version__,
                             "gymnasium": gymnasium.__version__, "numpy": np.__version__}},
               Path(run_dir) / CONFIG_FILE)


def load_config(run_dir: str | Path) -> TrainConfig:
    """The :class:`~dlo_course.config.TrainConfig` of a run, read from its ``config.json``."""
    path = Path(run_dir) / CONFIG_FILE
    return _config_in(read_json(path), path)


# --- the per-episode logs: progress.csv, validation.csv ---


def open_episode_log(path: Path, keep_episodes: int, columns: list[str] = PROGRESS_COLUMNS
                     ) -> tuple[Any, csv.DictWriter]:
    """Open ``progress.csv`` (or another per-episode CSV with ``columns``) for appending,
    keeping only the rows of the first ``keep_episodes`` episodes (rows written after the last
    resume state are replayed). Returns the open file and a CSV writer on it."""
    rows: list[dict[str, str]] = []
    if keep_episodes > 0 and path.exists():
        with path.open(newline="") as f:
            rows = [r for r in csv.DictReader(f)
                    if None not in r.values() and _episode_of(r, path) <= keep_episodes]
    f = path.open("w", newline="")
    writer = csv.DictWriter(f, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    f.flush()
    return f, writer


def _episode_of(row: dict[str, str], path: Path) -> int:
    try:
        return int(row["episode"])
    except (KeyError, TypeError, ValueError) as err:
        raise RunFileError(f"{path} is corrupt: a row without an episode number ({row})") \
            from err


def keep_episodes(path: Path, episodes: int) -> None:
    """Rewrite a per-episode CSV with only its rows up to ``episodes``, atomically."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = [row for row in reader if int(row["episode"]) <= episodes]
        fields = reader.fieldnames

    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)

    atomic_write(path, write)


def read_progress(run_dir: str | Path) -> dict[str, np.ndarray]:
    """The columns of a run's ``progress.csv`` as float arrays (empty cells become NaN)."""
    path = Path(run_dir) / PROGRESS_FILE
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: is {run_dir} a training run directory?")
    try:
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
    except (UnicodeDecodeError, csv.Error) as err:
        raise RunFileError(f"{path} is not a readable CSV file: {err}") from err
    if not rows:
        raise ValueError(f"{path} has no episode yet")
    missing = [c for c in ("episode", "transitions", "reward_mean") if c not in rows[0]]
    if missing:
        raise RunFileError(f"{path} is not a progress log: it has no {missing} column")
    try:
        return {key: np.array([float(r[key]) if r[key] != "" else np.nan for r in rows])
                for key in rows[0]}
    except (TypeError, ValueError) as err:  # a row cut short (None) or not a number
        raise RunFileError(f"{path} is truncated or corrupt: {err}") from err


# --- the resume state ---


def _rank_state_file(rank: int) -> str:
    return f"state_rank{rank}.pt"


def save_resume_state(run_dir: Path, agent: Any, buffer: Any, noise: Any, relabeller: Any,
                      counters: dict[str, Any], config: TrainConfig) -> None:
    """Save the resume state after ``counters["episodes_done"]`` episodes; every MPI rank
    calls it. Every rank saves its own state (buffer, noise, relabeller or ``None``, torch
    generator); rank 0 the shared networks and optimisers (``agent``, a
    :class:`~dlo_course.ddpg.DDPG`). The ``latest.json`` pointer moves only once every file
    is complete; then the older resume states are deleted and ``actor.pt`` and ``critic.pt``
    updated."""
    resume_root = run_dir / RESUME_DIR
    name = f"episode{counters['episodes_done']:06d}"
    state_dir = resume_root / name
    if mpi.is_root():
        state_dir.mkdir(parents=True, exist_ok=True)
    mpi.barrier()
    _torch_save({"buffer": buffer.state_dict(), "noise": noise.state_dict(),
                 "her": None if relabeller is None else relabeller.state_dict(),
                 "torch_rng": torch.get_rng_state()},
                state_dir / _rank_state_file(mpi.rank()))
    if mpi.is_root():
        _torch_save({"agent": agent.state_dict(), "counters": dict(counters),
                     "n_agents": mpi.size(), "config": config.to_dict()},
                    state_dir / SHARED_STATE_FILE)
    mpi.barrier()
    if mpi.is_root():
        # "checkpoint": the pointer's key since the first runs; they must still resume.
        write_json({"checkpoint": name, **counters}, resume_root / RESUME_POINTER)
        for old in resume_root.iterdir():
            if old.is_dir() and old.name != name:
                shutil.rmtree(old)
        _save_network_file(agent.actor, run_dir / ACTOR_FILE)
        _save_network_file(agent.critic, run_dir / CRITIC_FILE)


RESUMABLE_CHANGES = {"episodes", "out_dir", "checkpoint_every", "expected_agents",
                     "torch_threads", "validate_every"}
"""Configuration fields that may change when a run is resumed (e.g. to train for more
episodes)."""


def load_resume_state(run_dir: Path, agent: Any, buffer: Any, noise: Any, relabeller: Any,
                      config: TrainConfig) -> dict[str, Any] | None:
    """Restore the resume state of ``run_dir`` into this rank's objects (those of
    :func:`save_resume_state`); return the counters, or ``None`` if the run has none.

    Raises ``ValueError`` if the run had another number of agents, or a configuration that
    differs outside :data:`RESUMABLE_CHANGES`."""
    pointer = run_dir / RESUME_DIR / RESUME_POINTER
    if not pointer.exists():
        return None
    state_dir = run_dir / RESUME_DIR / _pointer_field(pointer, "checkpoint")
    shared = _load_state_file(state_dir / SHARED_STATE_FILE)
    if shared["n_agents"] != mpi.size():
        raise ValueError(f"{run_dir} was trained with {shared['n_agents']} agents; resume it "
                         f"with the same number of MPI ranks (got {mpi.size()})")
    # Through the dataclass, so that an option added since the resume state was written
    # reads as its default (off) instead of as a difference.
    saved = _config_in(shared, state_dir / SHARED_STATE_FILE).to_dict()
    now = config.to_dict()
    changed = sorted(k for k in now if k not in RESUMABLE_CHANGES and saved.get(k) != now[k])
    if changed:
        raise ValueError(f"cannot resume {run_dir}: the configuration differs in {changed}")
    mine = _load_state_file(state_dir / _rank_state_file(mpi.rank()))
    agent.load_state_dict(shared["agent"])
    buffer.load_state_dict(mine["buffer"])
    noise.load_state_dict(mine["noise"])
    if relabeller is not None:
        relabeller.load_state_dict(mine["her"])
    torch.set_rng_state(mine["torch_rng"])
    return dict(shared["counters"])


def _pointer_field(pointer: Path, key: str) -> Any:
    """A field of the resume state's pointer, ``latest.json``."""
    try:
        return read_json(pointer)[key]
    except (KeyError, TypeError) as err:
        raise RunFileError(f"{pointer} is corrupt: it has no {key!r}; start afresh with "
                           "--overwrite") from err


def _load_state_file(path: Path) -> dict[str, Any]:
    """One file of the resume state, with a clear error if it is missing or unreadable."""
    if not path.is_file():
        raise RunFileError(f"{path} is missing: the resume state is incomplete; start afresh "
                           "with --overwrite")
    try:
        # Our own files, holding NumPy arrays and generator states: not weights_only.
        state = torch.load(path, weights_only=False)
    except Exception as err:  # torch, zip and pickle raise many kinds
        raise RunFileError(f"{path} is not a readable resume state (truncated or corrupt?): "
                           f"{type(err).__name__}: {err}; start afresh with --overwrite") \
            from err
    if not isinstance(state, dict):
        raise RunFileError(f"{path} does not hold a resume state")
    return state


def delete_resume_state(run_dir: Path) -> None:
    """Remove a run's resume state (a run started afresh must not resume an old one)."""
    if (run_dir / RESUME_DIR).exists():
        shutil.rmtree(run_dir / RESUME_DIR)


def resumable_episodes(run_dir: Path) -> int | None:
    """Episodes per agent in the run's resume state, ``None`` if it has none."""
    pointer = Path(run_dir) / RESUME_DIR / RESUME_POINTER
    return int(_pointer_field(pointer, "episodes_done")) if pointer.is_file() else None


def save_best_actor(run_dir: Path, actor: torch.nn.Module, counters: dict[str, Any]) -> None:
    """Keep the actor that did best on the validation goals (``best_actor.pt``), with when
    and how well (``best.json``)."""
    _save_network_file(actor, run_dir / BEST_ACTOR_FILE)
    write_json({"episode": counters["best_episode"],
                "transitions": counters["best_transitions"],
                "done_rate": counters["best_done_rate"],
                "distance_mean": counters["best_distance"]}, run_dir / BEST_FILE)


def save_validated_actor(run_dir: Path, actor: torch.nn.Module, episode: int) -> Path:
    """Keep the actor that was just validated at ``episode`` (``validated/actor_epNNNNNN.pt``).

    The validation during training is small (30 goals by default: a few goals' difference
    decides which actor is "best"), so every candidate is kept for a larger validation to
    choose from afterwards; an actor file is about 0.3 MB."""
    path = Path(run_dir) / VALIDATED_DIR / f"actor_ep{episode:06d}.pt"
    path.parent.mkdir(parents=True, exist_ok=True)
    _save_network_file(actor, path)
    return path


def validated_actors(run_dir: str | Path) -> dict[int, Path]:
    """The actors :func:`save_validated_actor` kept in a run directory, by episode (empty for
    a run without validation, or one trained before they were kept)."""
    folder = Path(run_dir) / VALIDATED_DIR
    return {int(p.stem.removeprefix("actor_ep")): p
            for p in sorted(folder.glob("actor_ep*.pt"))}


# --- trained agents: the record, and shipping a run ---


def agent_dir(root: str | Path, n_nodes: int) -> Path:
    """The trained agent for ``n_nodes`` nodes in a folder of them (``root/nodes4``), the
    layout of ``data/checkpoints`` and of ``dlo-course reproduce --checkpoints``."""
    return Path(root) / f"nodes{n_nodes}"


def run_record(folder: str | Path) -> dict:
    """What a run's training cost and how it was set, from its ``config.json`` and
    ``progress.csv``: ranks, seed, commit, episodes per agent, transitions, wall time, and
    the settings that differ between presets. Missing files give missing keys."""
    folder = Path(folder)
    record: dict[str, Any] = {}
    config_file = folder / CONFIG_FILE
    if config_file.is_file():
        config = read_json(config_file)
        # Through the dataclass, so that a run older than an option reads as its default.
        cfg = _config_in(config, config_file)
        record.update(ranks=config.get("n_agents"), seed=cfg.seed, reduce=cfg.reduce,
                      commit=config.get("commit"), steps_per_episode=cfg.steps_per_episode,
                      updates_per_step=cfg.updates_per_step,
                      normalize_obs=cfg.ddpg.normalize_obs,
                      preactivation_l2=cfg.ddpg.preactivation_l2,
                      noise_sigma=cfg.ddpg.noise_sigma, her_k=cfg.her_k,
                      reset_between_episodes=cfg.reset_between_episodes,
                      batch_size=cfg.ddpg.batch_size, buffer_size=cfg.ddpg.buffer_size,
                      twin_critics=cfg.ddpg.twin_critics, policy_delay=cfg.ddpg.policy_delay,
                      target_noise=cfg.ddpg.target_noise, stop_at_goal=cfg.stop_at_goal)
        if "threshold" in cfg.env_kwargs:  # trained at another threshold than the env's 0.05
            record["train_threshold"] = cfg.env_kwargs["threshold"]
    try:
        progress = read_progress(folder)
    except (FileNotFoundError, ValueError):  # no run yet, or not one episode
        return record
    record.update(episodes_per_agent=int(progress["episode"][-1]),
                  transitions=int(progress["transitions"][-1]),
                  wall_time_h=float(progress["wall_time"][-1]) / 3600)
    return record


def training_record(agents_root: str | Path, n_nodes: int) -> dict:
    """The record of the trained agent for ``n_nodes`` in ``agents_root``: its
    ``record.json`` if it has one (a shipped agent), else :func:`run_record`."""
    folder = agent_dir(agents_root, n_nodes)
    if (folder / RECORD_FILE).is_file():
        return read_json(folder / RECORD_FILE)
    return run_record(folder)


SHIPPED_FILES = (ACTOR_FILE, CRITIC_FILE, CONFIG_FILE, PROGRESS_FILE)
"""The files every trained agent has; ``validation.csv`` and ``best.json`` come along when
the run has them."""


def ship_run(run_dir: str | Path, dest: str | Path, actor: str = "latest", **extra: Any
             ) -> Path:
    """Copy a finished run's networks, configuration, learning curve and validated actors
    (``validated/``) into ``dest`` (e.g. ``data/checkpoints/nodes4``) as a trained agent,
    without its resume state (the replay buffers), and write ``record.json``: what the training cost (:func:`run_record`) plus
    ``extra`` (e.g. ``commit=...`` for runs started before the trainer recorded it).

    Args:
        actor: "latest" ships the run's last actor; "best" the one that did best on the
            validation goals (``best_actor.pt``, runs with ``validate_every`` > 0), recorded
            as ``selected`` in ``record.json``. The cost recorded is the whole run's either way:
            knowing which actor was best took the training after it too.

    Returns:
        ``dest``.
    """
    run_dir, dest = Path(run_dir), Path(dest)
    if actor not in ("latest", "best"):
        raise ValueError(f"actor must be 'latest' or 'best', got {actor!r}")
    missing = [f for f in SHIPPED_FILES if not (run_dir / f).is_file()]
    if actor == "best" and not (run_dir / BEST_ACTOR_FILE).is_file():
        missing.append(f"{BEST_ACTOR_FILE} (train with validate_every > 0)")
    if missing:
        raise FileNotFoundError(f"{run_dir} is not a finished run: missing {missing}")
    dest.mkdir(parents=True, exist_ok=True)
    for name in SHIPPED_FILES:
        shutil.copy2(run_dir / name, dest / name)
    for name in (VALIDATION_FILE, BEST_FILE):
        if (run_dir / name).is_file():
            shutil.copy2(run_dir / name, dest / name)
        elif (dest / name).exists():
            (dest / name).unlink()  # left from a run shipped here before
    # Every validated actor goes along, so that a later, larger validation can choose among
    # them without the run directory (validated_actors reads them from either place).
    if (dest / VALIDATED_DIR).is_dir():
        shutil.rmtree(dest / VALIDATED_DIR)
    if (run_dir / VALIDATED_DIR).is_dir():
        shutil.copytree(run_dir / VALIDATED_DIR, dest / VALIDATED_DIR)
    if actor == "best":
        shutil.copy2(run_dir / BEST_ACTOR_FILE, dest / ACTOR_FILE)
        extra["selected"] = read_json(run_dir / BEST_FILE)
    # A run stopped between resume states: its networks are the last resume state's, so its
    # learning curve and record stop there too.
    done = resumable_episodes(run_dir)
    if done is not None:
        if actor == "best":  # a best actor found after the last resume state is still real
            done = max(done, int(extra["selected"]["episode"]))
        for name in (PROGRESS_FILE, VALIDATION_FILE):
            if (dest / name).is_file():
                keep_episodes(dest / name, done)
    record = {**run_record(dest), **{k: v for k, v in extra.items() if v is not None}}
    write_json(record, dest / RECORD_FILE)
    return dest
