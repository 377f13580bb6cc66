"""Benchmark (not a test): does lesson 9's own agent, trained by the student's ``play_episode``,
clear the hand-in's learning floor?

Trains the agent of lesson 9's section 7 as the notebook does
(:func:`dlo_course.submission.lesson_run_config`: the recipe on 2 nodes, one agent, episodes
that end at the goal), played by the solution's ``play_episode`` (``solutions/09_...``), then
runs lesson 13's graded protocol on it (:func:`dlo_course.submission.evaluate_graded`) and
prints its mean final distance against doing nothing's and the floor
(:data:`dlo_course.submission.FLOOR_SHARE`), with its done % on the graded goals. A stopped
run resumes (same ``--out``); ``--evaluate-at`` also evaluates the resume states of earlier
episodes, kept as copies of the actor (``actor_episodeNNN.pt``). The rows go to
``benchmarks/results/lesson09_own_agent.json`` (lesson 9 prints them); wall times are those
of the machine that ran it, shared with other work.

    python benchmarks/lesson09_own_agent.py --out runs/lesson09_own [--seed 0] \\
        [--episodes 100] [--evaluate-at 25 50 75]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import numpy as np

from dlo_course import pendulum, submission
from dlo_course.paths import REPO_ROOT
from dlo_course.rundir import read_progress
from dlo_course.trainer import train

RESULTS = Path(__file__).parent / "results" / "lesson09_own_agent.json"


def graded(actor: Path) -> dict:
    began = time.process_time()
    measured = submission.evaluate_graded(actor)
    final = float(np.mean([g["final_distance"] for g in measured["goals"]]))
    nothing = float(np.mean(measured["do_nothing_distances"]))
    return {"actor": str(actor), "done_percent": measured["done_percent"],
            "final_distance": round(final, 4), "do_nothing_distance": round(nothing, 4),
            "share_of_doing_nothing": round(final / nothing, 3),
            "floor": submission.FLOOR_SHARE, "passes": not submission.floor_problems(measured),
            "cpu_s": round(time.process_time() - began, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=int, default=submission.LESSON_EPISODES)
    parser.add_argument("--evaluate-at", type=int, nargs="*", default=[])
    args = parser.parse_args()

    play_episode = pendulum.earlier_answer("09_training_ddpg_on_the_dlo", "play_episode",
                                           REPO_ROOT / "solutions")
    rows = []
    for stop in sorted({*args.evaluate_at, args.episodes}):
        config = submission.lesson_run_config(args.out, episodes=stop)
        config.seed = args.seed
        train(config, resume=True, progress=False, play_episode=play_episode)
        kept = args.out / f"actor_episode{stop:03d}.pt"
        shutil.copyfile(args.out / "actor.pt", kept)
        progress = read_progress(args.out)
        row = {"episodes": stop, "transitions": int(progress["transitions"][-1]),
               "wall_time_min": round(float(progress["wall_time"][-1]) / 60, 1), **graded(kept)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    RESULTS.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
