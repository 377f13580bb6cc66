"""Benchmark (not a test): does our DDPG learn, and how fast does the trainer run?

1. One process, Pendulum-v1, 20 000 steps in 100 episodes of 200 steps, the paper's DDPG
   hyperparameters. Well-known DDPG implementations reach an average return of about -200 or
   better (the best possible is about -150) on the last episodes of such a run. Training
   returns include the exploration noise, which the paper's OU noise makes large (its
   stationary std is 0.57 of the action half-range), so the final actor is also evaluated
   without noise on 10 new episodes.
2. Trainer throughput (environment steps per second, all agents together, one update per
   step) with 1 and 2 MPI ranks, through the command line, on Pendulum-v1.

Usage (from the repository root; several minutes):

    python benchmarks/ddpg_pendulum.py [--steps 20000] [--throughput-episodes 5]
                                       [--parts learning,throughput]

Prints a report and writes benchmarks/results/ddpg_pendulum.{json,png} (the JSON keeps the
results of parts that were not rerun).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gymnasium
import numpy as np
import torch

from dlo_course.ddpg import load_network
from dlo_course.plots import plot_learning_curves
from dlo_course.rundir import read_progress
from dlo_course.config import TrainConfig
from dlo_course.trainer import train

RESULTS = Path(__file__).parent / "results"
EPISODE_STEPS = 200


def steady_rate(progress: dict[str, np.ndarray]) -> float:
    """Steps per second after the first episode (which has the start-up and the warm-up)."""
    t, n = progress["wall_time"], progress["transitions"]
    return float((n[-1] - n[0]) / (t[-1] - t[0]))


@torch.no_grad()
def evaluate(actor_path: Path, episodes: int = 10) -> list[float]:
    """Returns of the deterministic policy (no exploration noise) on new episodes."""
    actor = load_network(actor_path)
    env = gymnasium.make("Pendulum-v1")
    returns = []
    for i in range(episodes):
        obs, _ = env.reset(seed=10_000 + i)
        total, ended = 0.0, False
        while not ended:
            action = actor(torch.as_tensor(obs, dtype=torch.float32)[None])[0].numpy()
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            ended = terminated or truncated
        returns.append(total)
    return returns


def learning_run(steps: int, run_dir: Path) -> dict[str, float]:
    config = TrainConfig(env_id="Pendulum-v1", env_kwargs={}, episodes=steps // EPISODE_STEPS,
                         steps_per_episode=EPISODE_STEPS, checkpoint_every=10**9,
                         out_dir=str(run_dir), seed=0)
    start = time.perf_counter()
    train(config, progress=False, overwrite=True)
    elapsed = time.perf_counter() - start
    p = read_progress(run_dir)
    eval_returns = evaluate(run_dir / "actor.pt")
    return {"steps": int(p["transitions"][-1]), "episodes": len(p["episode"]),
            "mean_return_last10": float(p["reward_mean"][-10:].mean()),
            "eval_return_mean": float(np.mean(eval_returns)),
            "eval_return_std": float(np.std(eval_returns)),
            "best_return": float(p["reward_mean"].max()),
            "seconds": elapsed, "steps_per_s": float(p["transitions"][-1] / elapsed),
            "steps_per_s_steady": steady_rate(p)}


def mpi_throughput(n_ranks: int, episodes: int, run_dir: Path) -> dict[str, float]:
    mpiexec = Path(sys.executable).parent / "mpiexec"
    cmd = [str(mpiexec), "-n", str(n_ranks), sys.executable, "-m", "dlo_course.cli", "train",
           "--preset", "laptop", "--env", "Pendulum-v1", "--episodes", str(episodes),
           "--steps-per-episode", str(EPISODE_STEPS), "--out", str(run_dir), "--overwrite",
           "--no-progress"]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    elapsed = time.perf_counter() - start
    p = read_progress(run_dir)
    return {"ranks": n_ranks, "steps": int(p["transitions"][-1]), "seconds": elapsed,
            "steps_per_s_steady": steady_rate(p), "command": " ".join(cmd)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--throughput-episodes", type=int, default=5)
    parser.add_argument("--parts", default="learning,throughput",
                        help="comma-separated parts to run: learning, throughput")
    args = parser.parse_args()
    parts = set(args.parts.split(","))
    json_path = RESULTS / "ddpg_pendulum.json"
    results = json.loads(json_path.read_text()) if json_path.exists() else {}
    RESULTS.mkdir(parents=True, exist_ok=True)
    print(f"python {platform.python_version()}, torch {torch.__version__}, "
          f"{os.cpu_count()} cores", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        if "learning" in parts:
            run_dir = Path(tmp) / "pendulum"
            learn = results["learning"] = learning_run(args.steps, run_dir)
            print(f"[1] DDPG on Pendulum-v1, 1 process, {learn['steps']} steps "
                  f"({learn['episodes']} episodes of {EPISODE_STEPS}):\n"
                  f"    training return (with OU noise), mean of the last 10 episodes: "
                  f"{learn['mean_return_last10']:.1f} (best episode {learn['best_return']:.1f})\n"
                  f"    final actor without noise, 10 new episodes: "
                  f"{learn['eval_return_mean']:.1f} +- {learn['eval_return_std']:.1f}\n"
                  f"    {learn['seconds']:.0f} s, {learn['steps_per_s']:.0f} steps/s overall, "
                  f"{learn['steps_per_s_steady']:.0f} steps/s once learning", flush=True)
            fig = plot_learning_curves([run_dir],
                                       labels=["DDPG, Pendulum-v1, paper hyperparameters"])
            fig.savefig(RESULTS / "ddpg_pendulum.png", dpi=120)

        if "throughput" in parts:
            results["throughput"] = []
            for n in (1, 2):
                r = mpi_throughput(n, args.throughput_episodes, Path(tmp) / f"mpi{n}")
                results["throughput"].append(r)
                print(f"[2] trainer, {n} MPI rank(s): {r['steps_per_s_steady']:.0f} steps/s "
                      f"(all agents, one update per step), {r['steps']} steps in "
                      f"{r['seconds']:.0f} s\n    $ {r['command']}", flush=True)

    json_path.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
