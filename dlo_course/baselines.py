"""What a user would pick instead of the course's recipe: Stable-Baselines3's TD3 and SAC on
``DLOShape-v0``, trained off the shelf and evaluated with the course's own protocol.

``DLOShape-v0`` is a standard Gymnasium environment, so SB3 trains on it as it is. Two pieces
connect SB3 to the course:

* :func:`train_sb3` trains one SB3 agent into an *agent folder* (``sb3_model.zip`` beside a
  ``record.json``), resumably: every ``checkpoint_every`` steps it saves the model and its
  replay buffer, and a stopped run continues from there;
* :class:`PolicyActor` makes any policy that maps an observation to an action look like the
  course's actor (a torch module, (B, 6 + 6m) -> (B, 3)), so that
  :func:`dlo_course.evaluation.load_actor`, and with it ``dlo-course evaluate``,
  ``dlo-course reproduce`` and ``benchmarks/seeds_table1.py``, play an SB3 agent folder the
  way they play a trained DDPG agent: same goals, same forked episodes, same intervals.

SB3 is an optional extra (``pip install -c constraints.txt -e ".[sb3]"``); nothing else in
the course imports this module's SB3 parts.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn

from dlo_course.rundir import atomic_write

SB3_MODEL_FILE = "sb3_model.zip"
"""An SB3 agent folder's model (what ``model.save`` writes)."""
SB3_BUFFER_FILE = "sb3_replay_buffer.pkl"
"""Its replay buffer, kept for resuming only (not shipped)."""
SB3_STATE_FILE = "sb3_state.json"
"""The run's settings and progress: what a resume must match, and what the record reports."""
ALGORITHMS = ("td3", "sac")


def sb3():
    """The ``stable_baselines3`` module, or an ImportError that says how to install it."""
    try:
        import stable_baselines3
    except ImportError as err:
        raise ImportError("Stable-Baselines3 is an optional extra: "
                          "pip install -c constraints.txt -e \".[sb3]\"") from err
    return stable_baselines3


def algorithm_class(name: str):
    """SB3's class for ``name`` ("td3" or "sac")."""
    if name not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {name!r}")
    return getattr(sb3(), name.upper())


class PolicyActor(nn.Module):
    """Any deterministic policy as the course's actor.

    Args:
        policy: maps a (B, obs_dim) float32 array of observations to (B, 3) actions.
        obs_dim: its observation size (6 + 6m for m nodes), which the evaluation checks.

    ``forward`` takes a (B, obs_dim) tensor and returns the (B, 3) actions as a float32
    tensor, clipped to [-1, 1] (the environment's action space).
    """

    def __init__(self, policy: Callable[[np.ndarray], np.ndarray], obs_dim: int,
                 act_dim: int = 3):
        super().__init__()
        self.policy = policy
        self.init_kwargs = {"obs_dim": obs_dim, "act_dim": act_dim}  # as ddpg.Actor has them

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        actions = self.policy(obs.detach().cpu().numpy().astype(np.float32))
        return torch.as_tensor(np.clip(actions, -1.0, 1.0), dtype=torch.float32)


def load_sb3_actor(path: str | Path) -> PolicyActor:
    """An SB3 model file (``sb3_model.zip``, or its agent folder) as a :class:`PolicyActor`:
    SB3's deterministic action (``model.predict(obs, deterministic=True)``)."""
    path = Path(path)
    if path.is_dir():
        path = path / SB3_MODEL_FILE
    state = read_state(path.parent)
    model = algorithm_class(state["algorithm"]).load(path, device="cpu")
    obs_dim = int(np.prod(model.observation_space.shape))
    return PolicyActor(lambda obs: model.predict(obs, deterministic=True)[0], obs_dim)


def is_sb3_agent(path: str | Path) -> bool:
    """Whether ``path`` is an SB3 agent folder or model file."""
    path = Path(path)
    return (path / SB3_MODEL_FILE).is_file() or (path.is_file()
                                                 and path.name == SB3_MODEL_FILE)


def read_state(folder: str | Path) -> dict:
    return json.loads((Path(folder) / SB3_STATE_FILE).read_text())


def sb3_settings(algorithm: str) -> dict:
    """The SB3 keyword arguments :func:`train_sb3` uses, and why.

    SB3's defaults, except where the task's scale asks: TD3 has no exploration noise by
    default, and SB3's documentation pairs it with Gaussian noise of std 0.1 (the actions are
    in [-1, 1]); learning starts after 100 steps (SB3's default), so that the few thousand
    steps of this budget are almost all learning. SAC explores through its entropy term, with
    SB3's automatic temperature."""
    settings = {"learning_starts": 100, "verbose": 0, "device": "cpu"}
    if algorithm == "td3":
        from stable_baselines3.common.noise import NormalActionNoise

        settings["action_noise"] = NormalActionNoise(np.zeros(3), 0.1 * np.ones(3))
    return settings


def train_sb3(algorithm: str, out: str | Path, total_steps: int, env_kwargs: dict,
              max_episode_steps: int, seed: int = 0, checkpoint_every: int = 1000,
              progress: bool = True, overrides: dict | None = None) -> Path:
    """Train SB3's ``algorithm`` on ``DLOShape-v0`` for ``total_steps`` environment steps
    (transitions) into the agent folder ``out``; continue a stopped run found there.

    Args:
        env_kwargs: the environment's keyword arguments (e.g. ``{"n_nodes": 6,
            "threshold": 0.05}``, the shipped agent's).
        max_episode_steps: actions per training episode before the time limit.
        checkpoint_every: save the model and replay buffer every this many steps.
        overrides: SB3 keyword arguments on top of :func:`sb3_settings` (e.g. a small
            ``batch_size`` and ``learning_starts`` for a test of a few steps).

    Returns:
        ``out``, holding ``sb3_model.zip``, ``sb3_state.json`` and (until the run ends) the
        replay buffer.
    """
    import gymnasium as gym

    import dlo_course  # noqa: F401  (registers DLOShape-v0)

    cls = algorithm_class(algorithm)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    settings = {"algorithm": algorithm, "env_kwargs": env_kwargs, "seed": seed,
                "max_episode_steps": max_episode_steps, "overrides": sorted(overrides or {}),
                "sb3_version": sb3().__version__}
    env = gym.make("DLOShape-v0", max_episode_steps=max_episode_steps, **env_kwargs)
    if (out / SB3_MODEL_FILE).is_file():
        state = read_state(out)
        mismatch = {k: (state.get(k), v) for k, v in settings.items() if state.get(k) != v}
        if mismatch:
            raise ValueError(f"{out} holds another run ({mismatch}); choose another --out")
        model = cls.load(out / SB3_MODEL_FILE, env=env, device="cpu")
        if (out / SB3_BUFFER_FILE).is_file():
            model.load_replay_buffer(out / SB3_BUFFER_FILE)
        elif total_steps > state["steps"]:
            import warnings

            # A finished run kept no buffer (see the end of this function), and SB3 sized the
            # buffer for the first run's total: say so rather than continue as if resumed.
            warnings.warn(f"{out} holds a finished run of {state['steps']} steps whose replay "
                          f"buffer was not kept: continuing it to {total_steps} starts from an "
                          f"empty buffer of {model.buffer_size} transitions, not as a resume",
                          stacklevel=2)
        wall = state["wall_time_s"]
    else:
        # A buffer as long as the run never drops a transition, so it behaves as SB3's
        # default of a million does (sampling is uniform over what is stored), and its
        # checkpoint is 60 times smaller (350 MB for 16 458 steps with the default).
        model = cls("MlpPolicy", env, seed=seed,
                    **{"buffer_size": total_steps, **sb3_settings(algorithm),
                       **(overrides or {})})
        wall = 0.0
    from stable_baselines3.common.logger import Logger

    # SB3's default logger makes an empty folder in /tmp at every learn() call, even with
    # verbose=0; the course records the run in sb3_state.json instead.
    model.set_logger(Logger(folder=None, output_formats=[]))
    done = int(model.num_timesteps)
    started = time.monotonic()

    def save() -> None:
        # Each file written beside its final name, then renamed: a run killed while saving
        # keeps its previous checkpoint whole.
        for name, write in ((SB3_MODEL_FILE, model.save),
                            (SB3_BUFFER_FILE, model.save_replay_buffer)):
            partial = out / f"partial_{name}"
            write(partial)
            os.replace(partial, out / name)
        state = {**settings, "steps": int(model.num_timesteps), "total_steps": total_steps,
                 "wall_time_s": wall + time.monotonic() - started}
        atomic_write(out / SB3_STATE_FILE,
                     lambda tmp: Path(tmp).write_text(json.dumps(state, indent=1) + "\n"))

    from tqdm.auto import tqdm

    bar = tqdm(total=total_steps, initial=done, unit="step", disable=not progress,
               desc=f"SB3 {algorithm.upper()}")
    try:
        while model.num_timesteps < total_steps:
            chunk = min(checkpoint_every, total_steps - model.num_timesteps)
            before = model.num_timesteps
            model.learn(chunk, reset_num_timesteps=False)
            bar.update(model.num_timesteps - before)
            save()
    finally:
        bar.close()
        env.close()
    if (out / SB3_BUFFER_FILE).is_file():
        (out / SB3_BUFFER_FILE).unlink()  # only for resuming; the finished agent needs none
    return out
