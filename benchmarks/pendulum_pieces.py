"""Benchmark (not a test): lesson 04's Pendulum training and the floor of its grade.

1. Untrained actors (the library's ``Actor`` of lesson 04's size, 20 seeds) on the graded
   episodes (:func:`dlo_course.pendulum.evaluate_actor`): the mean returns an actor that did
   not learn gets, which the grade's floor (``pendulum.RETURN_FLOOR``) must stay far above.
2. The library's pieces trained by :func:`dlo_course.pendulum.train_pendulum` (lesson 04's
   DDPG, ``pendulum.TRAIN_STEPS`` steps, the tests' training too), seeds 0-2: the graded
   mean return of each actor, and the CPU seconds of each training (``time.process_time``,
   one torch thread: on a shared machine wall time says little).

Usage (from the repository root; about a minute of CPU):

    python benchmarks/pendulum_pieces.py [--seeds 3] [--steps 4000 6000 ...]

Prints a report; redirect it to benchmarks/results/pendulum_pieces.txt to commit it.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch

from dlo_course import pendulum
from dlo_course.ddpg import Actor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="trainings, seeds 0, 1, ...")
    parser.add_argument("--steps", type=int, nargs="+", default=[pendulum.TRAIN_STEPS],
                        help="training lengths to compare [pendulum.TRAIN_STEPS]")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"python {platform.python_version()}, torch {torch.__version__}, one torch thread")
    config = pendulum.PENDULUM_DDPG
    untrained = []
    for seed in range(20):
        torch.manual_seed(seed)
        actor = Actor(3, 1, -2.0, 2.0, config.hidden_sizes, config.final_init)
        untrained.append(float(np.mean(pendulum.evaluate_actor(actor))))
    print(f"[1] untrained actors, seeds 0-19, mean return over the {pendulum.GRADED_EPISODES} "
          f"graded episodes: from {min(untrained):.0f} to {max(untrained):.0f}", flush=True)
    print(f"    grade floor (pendulum.RETURN_FLOOR): {pendulum.RETURN_FLOOR:.0f}")
    for steps, seed in ((steps, seed) for steps in args.steps for seed in range(args.seeds)):
        began = time.process_time()
        agent, returns = pendulum.train_pendulum(steps=steps, seed=seed)
        cpu = time.process_time() - began
        graded = float(np.mean(pendulum.evaluate_actor(agent.actor)))
        print(f"[2] library pieces, {steps} steps, seed {seed}: graded mean return "
              f"{graded:.0f} (last training episode {returns[-1]:.0f}), {cpu:.0f} s of CPU",
              flush=True)


if __name__ == "__main__":
    main()
