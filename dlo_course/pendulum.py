"""DDPG on Pendulum-v1 from pieces: the training that lesson 04 runs with the student's replay
buffer (lesson 02), critic (lesson 03) and update (lesson 04), and the re-evaluation that
grades the actor it saves.

Pendulum-v1 (Gymnasium): swing a pendulum up from a random angle and keep it upright with a
torque in [-2, 2]. An episode is 200 steps, truncated, never terminated; a step's reward is
between about -16.3 and 0, so an episode's return between about -3300 and 0 (0: upright and
still from the first step). The rod takes hours to learn; this takes a minute, so a wrong
piece shows at once: the return stays where an untrained actor's is.

:func:`train_pendulum` is a plain loop (act with noise, store, sample, update) that takes the
pieces as arguments: the library's (:func:`library_pieces`) or a student's, which must behave
alike (``tests/test_pendulum.py`` checks that the solutions' pieces train bit for bit as the
library's). :data:`PENDULUM_DDPG` is a smaller DDPG than the paper's (two hidden layers of 64,
learning rates 1e-3): the paper's takes 20 000 steps and about 2.5 minutes of one core
(``benchmarks/results/ddpg_pendulum.txt``), too long for a test that trains once per piece.

The graded re-evaluation (:func:`evaluate_actor_file`) runs the saved actor, without noise, on
:data:`GRADED_EPISODES` episodes from fixed seeds; :data:`RETURN_FLOOR` is the mean return it
must beat, which no untrained actor reaches (measured: see its docstring).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import gymnasium
import numpy as np
import torch

from dlo_course.config import DDPGConfig
from dlo_course.ddpg import DDPG, Critic, load_network, policy_action
from dlo_course.noise import OUNoise
from dlo_course.replay_buffer import ReplayBuffer

ENV_ID = "Pendulum-v1"
EPISODE_STEPS = 200
"""Pendulum-v1's time limit: every episode is truncated after 200 steps."""

PENDULUM_DDPG = DDPGConfig(hidden_sizes=(64, 64), actor_lr=1e-3, critic_lr=1e-3,
                           batch_size=64, buffer_size=1_000_000)
"""The DDPG of lesson 04's Pendulum: the paper's but for smaller networks and a faster actor,
so that it learns in a few thousand steps (gamma, tau and the OU noise are the paper's). The
buffer holds a million transitions, as DDPG's (Lillicrap et al. 2016): never full in
:data:`TRAIN_STEPS`, so its size changes nothing for a correct buffer, which samples only
the rows it filled; a buffer that samples its empty rows too trains on zeros almost only
(with 50 000 rows, 12% of its samples were real after 6 000 steps, and it learned anyway:
-234, measured as :data:`RETURN_FLOOR` says)."""

TRAIN_STEPS = 6_000
"""Environment steps (30 episodes) of lesson 04's training, one update per step after the
warm-up: 5 000 updates, about 20 s of one core. 4 000 steps were too few for one seed in six
(:data:`RETURN_FLOOR`)."""

WARMUP = 1_000
"""Steps taken before the first update, so that the first batches are not five transitions
drawn again and again."""

GRADED_EPISODES = 10
EVALUATION_SEED = 10_000
"""The graded episodes start from ``env.reset(seed=EVALUATION_SEED + i)``, i < 10: the
benchmark's (``benchmarks/ddpg_pendulum.py``) and lesson 04's evaluation episodes."""

RETURN_FLOOR = -400.0
"""The mean return over the graded episodes that a handed-in actor must beat. Measured with
:func:`evaluate_actor` (``benchmarks/pendulum_pieces.py``, its output committed in
``benchmarks/results/pendulum_pieces.txt``): untrained actors of lesson 04's size get mean
returns between -1108 and -1068 (20 seeds); measured once the same way, untrained actors of
the paper's size -1116 to -1067 (5 seeds), a constant torque -1072 at best (0) and -1589
at worst (+2). Lesson 04's training with the library's pieces, seeds 0-5: -110 to -112
with :data:`TRAIN_STEPS` = 6 000; with 4 000 steps -111 to -129, but -562 for seed 1, so a
student's right pieces, whose random draws need not follow the library's, would have missed
the floor about once in six. The mistakes of ``tests/test_pendulum.py`` end at -1094 to
-1720 (one stops the training with an error). An actor above -400 swings the pendulum up and
holds it in most graded episodes; none that did not learn comes near."""

ACTOR_FILE = "04_pendulum_actor.pt"
"""The actor lesson 04 saves beside the notebook (``Path.cwd()``), handed in with it."""

MAX_ACTOR_BYTES = 2**20
"""The largest handed-in Pendulum actor the grader reads (lesson 04's is about 20 kB)."""


def earlier_answer(notebook: str, name: str, folder: str | Path | None = None) -> Any:
    """The student's answer ``name`` (the function or class an exercise cell defines) from
    their notebook ``notebook`` (e.g. ``"02_experience_replay"``) in ``folder``, by default
    ``Path.cwd()``, where Jupyter runs a notebook: the lessons beside lesson 04. The notebook
    is run as the grader runs it (its setup cells, then its exercise cells up to that one),
    not executed whole. Returns None if there is no such notebook; raises
    :class:`dlo_course.grading.runner.ExerciseError` if it has no such exercise.

    Not among the notebook helpers an exercise cell may call
    (:data:`dlo_course.grading.delegation.LIBRARY_HELPERS`): pointed at the course's
    solutions, it would hand an exercise their answers."""
    from dlo_course.grading.runner import ExerciseNotebook

    path = (Path.cwd() if folder is None else Path(folder)) / f"{notebook}.ipynb"
    if not path.is_file():
        return None
    return ExerciseNotebook.from_path(path).load(name)


class _LibraryBuffer(ReplayBuffer):
    """The library's buffer with lesson 02's ``add(..., terminated, truncated)``: stores
    ``done = terminated``, as :mod:`dlo_course.trainer` does."""

    def add(self, obs, act, rew, next_obs, terminated, truncated=False):  # noqa: D102
        super().add(obs, act, rew, next_obs, terminated)


def library_pieces() -> dict[str, Any]:
    """The library's pieces, under the names :func:`train_pendulum` takes: ``buffer_class``
    (lesson 02's RingBuffer), ``critic_class`` (lesson 03's Critic) and ``update`` (lesson
    04's ddpg_update, here :meth:`DDPG.update`)."""
    return {"buffer_class": _LibraryBuffer, "critic_class": Critic, "update": DDPG.update}


def as_tensors(batch: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    """A buffer's sample as lesson 04's ``ddpg_update`` takes it: float32 tensors, ``rew``
    and ``done`` reshaped from (B,) to (B, 1), the critic's output shape."""
    out = {k: torch.as_tensor(np.asarray(batch[k]), dtype=torch.float32)
           for k in ("obs", "act", "next_obs")}
    for k in ("rew", "done"):
        out[k] = torch.as_tensor(np.asarray(batch[k]), dtype=torch.float32).reshape(-1, 1)
    return out


def train_pendulum(buffer_class: Callable[..., Any] = _LibraryBuffer,
                   critic_class: Callable[..., torch.nn.Module] = Critic,
                   update: Callable[[DDPG, dict[str, torch.Tensor]], Any] = DDPG.update,
                   steps: int = TRAIN_STEPS, seed: int = 0,
                   config: DDPGConfig = PENDULUM_DDPG, warmup: int = WARMUP,
                   on_episode: Callable[[int, float], None] | None = None
                   ) -> tuple[DDPG, list[float]]:
    """Train DDPG on Pendulum-v1 with the given pieces, one update per step.

    Args:
        buffer_class: ``buffer_class(obs_dim, act_dim, capacity, seed=...)`` with lesson 02's
            ``add(obs, act, rew, next_obs, terminated, truncated)``, ``sample(B)`` and
            ``len()``.
        critic_class: ``critic_class(obs_dim, act_dim, hidden_sizes, final_init)``, an
            ``nn.Module`` mapping (B, obs_dim), (B, act_dim) to (B, 1) Q-values.
        update: ``update(agent, batch)``: one DDPG update of ``agent`` (a :class:`DDPG`)
            on a batch of :func:`as_tensors`.
        steps: environment steps (``steps // 200`` episodes).
        seed: seeds the networks, the buffer's draws, the noise and the episodes' starts.
        config: the DDPG's hyperparameters.
        warmup: steps before the first update.
        on_episode: called with (episode number from 1, its return) after each episode.

    Returns:
        The trained agent and the return of each training episode (with exploration noise).
    """
    torch.manual_seed(seed)
    env = gymnasium.make(ENV_ID)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    agent = DDPG(obs_dim, act_dim, env.action_space.low, env.action_space.high, config,
                 critic_class=critic_class)
    buffer = buffer_class(obs_dim, act_dim, config.buffer_size, seed=seed)
    noise = OUNoise(act_dim, config.noise_theta, config.noise_sigma, config.noise_mu,
                    seed=seed + 1)
    returns: list[float] = []
    obs, _ = env.reset(seed=seed)
    noise.reset()
    total = 0.0
    for step in range(steps):
        action = agent.act(obs, noise)
        next_obs, reward, terminated, truncated, _ = env.step(action)
        buffer.add(obs, action, reward, next_obs, terminated, truncated)
        obs, total = next_obs, total + float(reward)
        if step + 1 >= warmup:
            update(agent, as_tensors(buffer.sample(config.batch_size)))
        if terminated or truncated:
            returns.append(total)
            if on_episode is not None:
                on_episode(len(returns), total)
            obs, _ = env.reset(seed=seed + len(returns))
            noise.reset()
            total = 0.0
    env.close()
    return agent, returns


def evaluate_actor(actor: torch.nn.Module, episodes: int = GRADED_EPISODES,
                   seed: int = EVALUATION_SEED) -> list[float]:
    """Returns of the deterministic policy (no noise) on ``episodes`` Pendulum-v1 episodes
    that start from ``env.reset(seed=seed + i)``.

    Args:
        actor: any module mapping (B, 3) observations to (B, 1) torques in [-2, 2].
    """
    env = gymnasium.make(ENV_ID)
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        total, ended = 0.0, False
        while not ended:
            obs, reward, terminated, truncated, _ = env.step(policy_action(actor, obs[None])[0])
            total += float(reward)
            ended = terminated or truncated
        returns.append(total)
    env.close()
    return returns


def evaluate_actor_file(path: str | Path) -> dict[str, Any]:
    """The graded re-evaluation of a saved actor (:func:`dlo_course.ddpg.load_network`, which
    reads weights only): its returns on the :data:`GRADED_EPISODES` graded episodes, their
    mean, and whether the mean beats :data:`RETURN_FLOOR`."""
    actor = load_network(path)
    if type(actor).__name__ != "Actor":
        raise ValueError(f"{path} holds a {type(actor).__name__}, not an actor")
    returns = evaluate_actor(actor)
    mean = float(np.mean(returns))
    return {"returns": returns, "mean_return": mean, "floor": RETURN_FLOOR,
            "passed": bool(mean > RETURN_FLOOR)}
