"""Benchmark (not a test): Stable-Baselines3's TD3 and SAC, off the shelf, against the course's
recipe at equal transitions, on Table I's 8 cells of 6 nodes.

The budget and the task are the shipped 6-node agent's (data/checkpoints/nodes6): its
environment settings (6 nodes, trained at 0.05 m, so an episode ends at the goal), its
60-action episodes and its transitions (16 458 over its 2 ranks); SB3 trains one process for
as many steps. SB3's settings are its defaults except where :func:`dlo_course.baselines.
sb3_settings` says why. Every ``--checkpoint-every`` steps the model and its replay buffer are
saved: the same command continues a stopped run.

    pip install -c constraints.txt -e ".[sb3]"
    python benchmarks/sb3_vs_recipe.py train --algo td3 --seed 0     # about an hour per 16 500 steps on a free core
    python benchmarks/sb3_vs_recipe.py train --algo sac --seed 0
    mpiexec -n 2 python benchmarks/sb3_vs_recipe.py table

``train`` trains in ``runs/sb3_ALGO_n6_sSEED`` and, when finished, copies the agent to
``data/checkpoints/baselines/sb3_ALGO_n6_seedSEED`` (model, settings, record). ``table``
evaluates every finished agent there and the shipped 6-node agent with the course's protocol
(100 episodes per cell, the same goal draws; cached in benchmarks/results/seeds/cache under
each model's digest) and writes ``benchmarks/results/sb3_vs_recipe.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from pathlib import Path

from dlo_course import mpi
from dlo_course.baselines import (ALGORITHMS, SB3_MODEL_FILE, SB3_STATE_FILE, read_state,
                                  train_sb3)
from dlo_course.paths import REPO_ROOT
from dlo_course.reproduce import evaluate_cells, read_paper_table
from dlo_course.rundir import load_config, read_json

sys.path.insert(0, str(Path(__file__).parent))
from seeds_table1 import (CACHE, EPISODES, GOAL_SEED, MAX_STEPS, _layout,  # noqa: E402
                          cells)

NODES = 6
SHIPPED = REPO_ROOT / "data" / "checkpoints" / f"nodes{NODES}"
BASELINES = REPO_ROOT / "data" / "checkpoints" / "baselines"
OUT = Path(__file__).parent / "results" / "sb3_vs_recipe.md"


def shipped_budget() -> tuple[dict, int, int]:
    """(env_kwargs, steps per episode, transitions) of the shipped 6-node agent."""
    config = load_config(SHIPPED)
    record = read_json(SHIPPED / "record.json")
    return dict(config.env_kwargs), config.steps_per_episode, int(record["transitions"])


def train(algorithm: str, seed: int, steps: int | None, checkpoint_every: int) -> Path:
    env_kwargs, episode_steps, transitions = shipped_budget()
    run = REPO_ROOT / "runs" / f"sb3_{algorithm}_n{NODES}_s{seed}"
    train_sb3(algorithm, run, total_steps=steps or transitions, env_kwargs=env_kwargs,
              max_episode_steps=episode_steps, seed=seed, checkpoint_every=checkpoint_every)
    dest = BASELINES / f"sb3_{algorithm}_n{NODES}_seed{seed}"
    dest.mkdir(parents=True, exist_ok=True)
    for name in (SB3_MODEL_FILE, SB3_STATE_FILE):
        shutil.copy2(run / name, dest / name)
    state = read_state(run)
    record = {"algorithm": f"SB3 {algorithm.upper()}", "transitions": state["steps"],
              "ranks": 1, "seed": seed, "wall_time_h": state["wall_time_s"] / 3600,
              "sb3_version": state["sb3_version"],
              "command": f"python benchmarks/sb3_vs_recipe.py train --algo {algorithm} "
                         f"--seed {seed}" + (f" --steps {steps}" if steps else "")}
    (dest / "record.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"shipped {dest}")
    return dest


def table() -> str:
    agents = {"course recipe (data/checkpoints/nodes6)": SHIPPED}
    for algorithm in ALGORITHMS:
        for folder in sorted(BASELINES.glob(f"sb3_{algorithm}_n{NODES}_seed*")):
            agents[f"SB3 {algorithm.upper()} ({folder.name})"] = folder
    rows = {}
    for i, (label, folder) in enumerate(agents.items()):
        rows[label] = evaluate_cells(_layout(i, folder, NODES, "sb3"), EPISODES, MAX_STEPS,
                                     GOAL_SEED, cells=cells(NODES, without=True),
                                     protocol="test", cache=CACHE)
    if not mpi.is_root():
        return ""
    paper = read_paper_table()
    lines = ["# SB3 off the shelf against the course's recipe, 6 nodes", "",
             "Made by `mpiexec -n 2 python benchmarks/sb3_vs_recipe.py table` (how each agent "
             "was trained: the script's docstring and each agent's record.json). Done % on "
             f"Table I's test goals, {EPISODES} episodes per cell, at most {MAX_STEPS} actions, "
             "with the 95% Wilson interval; the same goal draws for every agent.", ""]
    header = "| reinit. | database | threshold | paper |"
    for label, folder in agents.items():
        record = read_json(folder / "record.json")
        header += f" {label}, {record['transitions']} transitions |"
    lines += [header, "|---|---|---|---|" + "---|" * len(agents)]
    for cell in cells(NODES, without=True):
        line = (f"| {cell.reinit} | {cell.database} | {cell.threshold:g} m | "
                f"{paper[cell.key]['done_percent']:.1f} |")
        for label in agents:
            row = next(r for r in rows[label] if r["cell"] == cell)
            line += (f" {row['done_percent']:.0f} [{row['done_ci_low']:.0f}, "
                     f"{row['done_ci_high']:.0f}] |")
        lines.append(line)
    text = "\n".join(lines) + "\n"
    OUT.write_text(text)
    print(text)
    return text


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("train", "table"))
    parser.add_argument("--algo", choices=ALGORITHMS, help="train: the SB3 algorithm")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None,
                        help="train: environment steps (default: the shipped agent's "
                             "transitions)")
    parser.add_argument("--checkpoint-every", type=int, default=500,
                        help="train: save the model and replay buffer every this many steps")
    args = parser.parse_args(argv)
    if args.command == "train":
        if args.algo is None:
            parser.error("train wants --algo td3|sac")
        train(args.algo, args.seed, args.steps, args.checkpoint_every)
    else:
        table()


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    main(sys.argv[1:])
