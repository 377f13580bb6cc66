"""Benchmark (not a test): which training levers matter, on the 4-node task at equal transitions.

Trains the paper's settings, the `course` preset, the `recipe` preset and the recipe with each
lever removed in turn, every variant for the same number of rod transitions on 2 MPI ranks,
then evaluates each final actor with Table I's protocol (with reinitialisation, 0.05 m and
0.03 m) on the paper's test goals (`small-test`) and on goals drawn from the whole small
database. Everything is resumable: a variant's run resumes from its last checkpoint, a finished
evaluation is kept in a JSON file, so the command can be stopped and started again (it is
several hours of work on two cores).

    mpiexec -n 2 python benchmarks/ablation.py run [--budget 3600] [--only recipe ...]
    python benchmarks/ablation.py report

`run` trains and evaluates the variants not yet done, in the order of VARIANTS, then writes
the report; `report` writes `benchmarks/results/ablation/` (README.md with the table,
ablation.csv, curves.png) from whatever is finished. Runs go to `runs/ablation/NAME`; a
finished variant's record (its evaluation, progress, configuration, last checkpoint's counts
and final actor, not its replay buffer) is kept in `benchmarks/results/ablation/runs/NAME`,
which `report` reads when `runs/` does not have it: a report made on another machine, or
after `runs/` was cleaned, still has every finished variant.

No variant selects its actor on validation goals (`validate_every=0`): the comparison is of
what each set of levers has learnt after the budget, not of the selection.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np

from dlo_course import mpi
from dlo_course.evaluation import evaluate_thresholds
from dlo_course.rundir import read_progress
from dlo_course.config import TrainConfig, preset
from dlo_course.trainer import train

RUNS = Path("runs/ablation")  # changed by --runs
RESULTS = Path(__file__).parent / "results" / "ablation"  # changed by --results
NODES = 4
THRESHOLDS = (0.05, 0.03)
GOALS = {"test": "small-test", "whole": "small"}
PAPER_DONE = {0.05: 99.8, 0.03: 88.7}  # Table I, 4 nodes, small database, with reinit
AUTHORS_AGENT_WHOLE = 67.5  # the authors' published 4-node agent on the whole small database
# The table in benchmarks/results/ablation/ was made with this budget: its nine variants took
# about 3 hours of 2 cores, training and evaluation; the 40 000 would take a day.
BUDGET = 3_600


def _recipe(**changes) -> TrainConfig:
    ddpg_changes = {k: changes.pop(k) for k in list(changes)
                    if k in {f.name for f in dataclasses.fields(preset("recipe").ddpg)}}
    config = preset("recipe", validate_every=0, **changes)
    return dataclasses.replace(config, ddpg=dataclasses.replace(config.ddpg, **ddpg_changes))


def variants() -> dict[str, tuple[str, TrainConfig]]:
    """name -> (what it tests, configuration); every one on 4 nodes and meant for 2 ranks."""
    paper = preset("paper", env_kwargs={"n_nodes": NODES}, expected_agents=2,
                   checkpoint_every=2)
    course = preset("course", env_kwargs={"n_nodes": NODES})
    return {
        "recipe": ("every lever on", _recipe()),
        "recipe-no-her": ("no hindsight relabelling (her_k 0)", _recipe(her_k=0)),
        "paper": ("the paper's DDPG and settings (300-step episodes, batch 128)", paper),
        "course": ("the course preset: input scaling, pre-tanh penalty, sigma 0.15, "
                   "60-step episodes, 2 updates per step", course),
        "recipe-no-td3": ("no twin critics, no policy delay, no target smoothing",
                          _recipe(twin_critics=False, policy_delay=1, target_noise=0.0)),
        "recipe-reset": ("the world rebuilt before every training episode",
                         _recipe(reset_between_episodes=True)),
        "recipe-paper-batch": ("the paper's batch (128), buffer (1e6) and 1 update per step",
                               _recipe(batch_size=128, buffer_size=1_000_000,
                                       updates_per_step=1)),
        "recipe-stop-at-goal": ("episodes end at the goal (stop_at_goal, the first "
                                "recipe) instead of running on as in the paper",
                                _recipe(stop_at_goal=True)),
        "recipe-train-at-0.05": ("trained at the paper's 0.05 m instead of 0.03 m",
                                 _recipe(env_kwargs={"n_nodes": NODES})),
    }


def transitions_done(run: Path) -> int:
    """Transitions of the run's last checkpoint (0 if none): what a resume starts from."""
    pointer = run / "checkpoints" / "latest.json"
    return int(json.loads(pointer.read_text())["transitions"]) if pointer.is_file() else 0


def train_to_budget(name: str, config: TrainConfig, budget: int) -> Path:
    """Train ``config`` until its transitions (all agents) reach ``budget``, one checkpoint
    interval at a time, so that every variant stops at the first checkpoint past the budget
    whatever its episode length; a killed run resumes from its last checkpoint."""
    run = RUNS / name
    while transitions_done(run) < budget:
        pointer = run / "checkpoints" / "latest.json"
        episodes = (json.loads(pointer.read_text())["episodes_done"] if pointer.is_file()
                    else 0) + config.checkpoint_every
        train(dataclasses.replace(config, episodes=episodes, out_dir=str(run)),
              resume=True, progress=False)
    return run


KEPT_FILES = ("evaluation.json", "progress.csv", "config.json", "actor.pt",
              "checkpoints/latest.json")
"""What a finished variant leaves in the repository (its replay buffer stays in runs/)."""


def keep_run(name: str, run: Path) -> Path:
    """Copy the record of a finished variant into RESULTS/runs/NAME."""
    kept = RESULTS / "runs" / name
    for relative in KEPT_FILES:
        (kept / relative).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(run / relative, kept / relative)
    return kept


def finished_run(name: str) -> Path | None:
    """Where the finished variant ``name`` is: its run, else its kept record, else None."""
    for run in (RUNS / name, RESULTS / "runs" / name):
        if (run / "evaluation.json").is_file():
            return run
    return None


def evaluate_run(name: str, run: Path, episodes: int) -> dict:
    """Table I's protocol on the run's actor, both goal sets; cached in ``evaluation.json``."""
    cache = run / "evaluation.json"
    if cache.is_file():
        return json.loads(cache.read_text())
    result = {}
    for key, goals in GOALS.items():
        scored = evaluate_thresholds(run, goals, THRESHOLDS, reinitialize=True,
                                     episodes=episodes, seed=0, n_nodes=NODES,
                                     show_progress=False)
        if mpi.is_root():
            result[key] = {str(t): scored[t][0].as_dict() for t in THRESHOLDS}
    if mpi.is_root():
        cache.write_text(json.dumps(result, indent=2) + "\n")
    mpi.barrier()
    return json.loads(cache.read_text())


def run(budget: int, episodes: int, only: list[str]) -> None:
    chosen = variants()
    unknown = set(only) - set(chosen)
    if unknown:
        raise SystemExit(f"unknown variants {sorted(unknown)}; choose from {list(chosen)}")
    for name, (_, config) in chosen.items():
        if only and name not in only:
            continue
        done = finished_run(name)
        if done is not None and transitions_done(done) >= budget:
            if mpi.is_root():
                print(f"{name}: already done ({done})", flush=True)
            continue
        if mpi.is_root():
            print(f"{name}: training to {budget} transitions", flush=True)
        run_dir = train_to_budget(name, config, budget)
        if mpi.is_root():
            print(f"{name}: evaluating", flush=True)
        evaluate_run(name, run_dir, episodes)
        if mpi.is_root():
            keep_run(name, run_dir)
            report()


def _done_cell(summary: dict) -> str:
    return (f"{summary['done_percent']:.0f} ({summary['done_ci_low']:.0f}-"
            f"{summary['done_ci_high']:.0f})")


def report() -> Path:
    """Write the table and the curves of every finished variant."""
    import matplotlib.pyplot as plt

    RESULTS.mkdir(parents=True, exist_ok=True)
    rows, curves = [], {}
    for name, (what, config) in variants().items():
        run_dir = finished_run(name)
        if run_dir is None:
            continue
        result = json.loads((run_dir / "evaluation.json").read_text())
        progress = read_progress(run_dir)
        curves[name] = progress
        rows.append({
            "variant": name, "what": what,
            "episodes_per_agent": int(progress["episode"][-1]),
            "transitions": transitions_done(run_dir),
            "hours": float(progress["wall_time"][-1]) / 3600,
            **{f"{key}_{t}": result[key][str(t)] for key in GOALS for t in THRESHOLDS},
        })
    with open(RESULTS / "ablation.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["variant", "transitions", "episodes_per_agent", "hours"]
                        + [f"{key}_done_percent_{t}" for key in GOALS for t in THRESHOLDS])
        for r in rows:
            writer.writerow([r["variant"], r["transitions"], r["episodes_per_agent"],
                             f"{r['hours']:.2f}"]
                            + [f"{r[f'{key}_{t}']['done_percent']:.1f}"
                               for key in GOALS for t in THRESHOLDS])
    lines = [
        "# Ablation of the training levers (4 nodes, 2 ranks, equal transitions)",
        "",
        "Written by `python benchmarks/ablation.py report` after "
        f"`mpiexec -n 2 python benchmarks/ablation.py run --budget {BUDGET}` (see the script's "
        "docstring). Each "
        "variant trained until its transitions (both agents) reached the budget, stopping at "
        "its first checkpoint past it; its final actor evaluated with Table I's protocol, "
        f"with reinitialisation, {rows[0]['test_0.05']['episodes'] if rows else '?'} "
        "episodes per goal set, goal draw seed 0: on the paper's test goals "
        "(`small-test`) and on goals drawn from the whole small database. Done % with its 95% "
        f"Wilson interval. The paper: {PAPER_DONE[0.05]}% at 0.05 m and {PAPER_DONE[0.03]}% at "
        f"0.03 m on its test goals after 604,800 transitions; the authors' agent reaches "
        f"{AUTHORS_AGENT_WHOLE}% of the whole small database at 0.05 m.",
        "",
        "| variant | what it tests | transitions | hours | test goals 0.05 m | 0.03 m | "
        "whole database 0.05 m | 0.03 m |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['variant']} | {r['what']} | {r['transitions']:,} | "
                     f"{r['hours']:.2f} | "
                     + " | ".join(_done_cell(r[f"{key}_{t}"]) for key in GOALS
                                  for t in THRESHOLDS) + " |")
    missing = [n for n in variants() if n not in curves]
    if missing:
        lines += ["", "Not run yet: " + ", ".join(f"`{n}`" for n in missing) + "."]
    lines += ["", "Training curves: `curves.png`. What the table says, and how much of it is "
              "the noise of one seed: `docs/design.md`, \"Which levers matter\"."]
    (RESULTS / "README.md").write_text("\n".join(lines) + "\n")

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    for name, p in curves.items():
        window = max(1, math.ceil(len(p["episode"]) / 20))
        kernel = np.ones(window) / window
        x = p["transitions"][window - 1:]
        axes[0].plot(x, np.convolve(p["distance_mean"], kernel, "valid"), label=name)
        axes[1].plot(x, np.convolve(p["success_rate"], kernel, "valid"), label=name)
    axes[0].set_ylabel("final mean node distance (m)")
    axes[1].set_ylabel("share of training episodes reaching 0.05 m")
    for ax in axes:
        ax.set_xlabel("transitions (both agents)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize="small")
    fig.suptitle("Training episodes, running mean over 1/20 of each run (noise and "
                 "hindsight goals make these noisier than the evaluation)", fontsize="medium")
    fig.savefig(RESULTS / "curves.png", dpi=120)
    plt.close(fig)
    return RESULTS / "README.md"


def main() -> None:
    global RUNS, RESULTS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run_parser = sub.add_parser("run", help="train and evaluate what is not done yet")
    run_parser.add_argument("--budget", type=int, default=BUDGET,
                            help="transitions per variant, both agents together")
    run_parser.add_argument("--episodes", type=int, default=100,
                            help="test episodes per goal set")
    run_parser.add_argument("--only", nargs="*", default=[], help="variant names")
    report_parser = sub.add_parser("report",
                                   help="write the table and curves of the finished variants")
    for p in (run_parser, report_parser):
        p.add_argument("--runs", type=Path, default=RUNS, help="runs of the variants")
        p.add_argument("--results", type=Path, default=RESULTS, help="where the report goes")
    args = parser.parse_args()
    RUNS, RESULTS = args.runs, args.results
    if args.command == "run":
        if mpi.size() != 2 and mpi.is_root():
            print(f"warning: the ablation is meant for 2 ranks, running {mpi.size()}",
                  file=sys.stderr)
        run(args.budget, args.episodes, args.only)
    else:
        print(report())


if __name__ == "__main__":
    main()
