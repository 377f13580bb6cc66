"""Benchmark (not a test): where lesson 13's own-agent checks draw their lines.

The points of ``own_agent_report`` go to a 2-node actor that behaves like no shipped actor
(``submission.LIKENESS_TOLERANCE``: mean absolute action difference on the grader's probe
observations) and that learned something (``submission.FLOOR_SHARE``: on the graded protocol
its mean final distance is at most that share of what doing nothing leaves). This script
measures, with the current scene and the current shipped agents:

* the action difference between shipped actors of one node count, trained apart (the seeds);
* the shipped 2-node actor changed as a student who wants the points without training would
  (one weight by 1e-6, all weights x 1.0001, Gaussian noise of a share of each tensor's
  spread): action difference and graded-protocol distance, which shows the grey zone;
* untrained actors (fresh seeds; small and large output layers; with the recipe's input
  scaling) and a do-nothing actor (output layer zero) on the graded protocol;
* any actor files or run directories given (e.g. lesson 9's ``reports/lessons/09/recipe_n2``).

    python benchmarks/own_agent_floor.py [AGENT ...] [--seeds 4] [--noise 0.01 0.05 0.1 0.2]

One graded-protocol evaluation costs about 9 s of CPU.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from itertools import combinations
from pathlib import Path

import numpy as np
import torch

from dlo_course import submission
from dlo_course.ddpg import Actor, load_network, save_network
from dlo_course.evaluation import load_actor
from dlo_course.paths import AGENTS_DIR, DATA_DIR
from dlo_course.task import observation_size


def changed_copy(source: Path, dest: Path, change) -> Path:
    """``source``'s actor with ``change(actor)`` applied in place, saved to ``dest``."""
    actor = load_network(source)
    with torch.no_grad():
        change(actor)
    save_network(actor, dest)
    return dest


def fresh_actor(dest: Path, seed: int, final_init: float, scaled_like: Path | None) -> Path:
    torch.manual_seed(seed)
    kwargs = {}
    if scaled_like is not None:
        reference = load_network(scaled_like).init_kwargs
        kwargs = {k: reference[k] for k in ("obs_offset", "obs_scale") if k in reference}
    save_network(Actor(observation_size(2), 3, final_init=final_init, **kwargs), dest)
    return dest


def row(label: str, path: Path) -> None:
    began = time.process_time()
    measured = submission.evaluate_graded(path)
    final = np.mean([g["final_distance"] for g in measured["goals"]])
    nothing = np.mean(measured["do_nothing_distances"])
    behaviour = submission.actor_behaviour(path)
    near = submission.shipped_likeness(behaviour["probe_actions"], behaviour["n_nodes"])
    likeness = f"{near[0][1]:.2g} ({near[0][0]})" if near else "-"
    verdict = submission.likeness_problems(behaviour) + submission.floor_problems(measured)
    print(f"| {label} | {measured['done_percent']:.0f} | {final:.4f} | {nothing:.4f} | "
          f"{final / nothing:.2f} | {likeness} | {'points' if not verdict else '0'} | "
          f"{time.process_time() - began:.0f} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("agents", nargs="*", type=Path)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--noise", type=float, nargs="*", default=[0.01, 0.05, 0.1, 0.2])
    args = parser.parse_args()

    print("Action difference between shipped actors of one node count (mean |a - b| on "
          f"{submission.PROBE_COUNT} probe observations):\n")
    actors = {p.relative_to(DATA_DIR).as_posix(): load_actor(p)
              for p in submission.shipped_actor_files()}
    actions = {name: submission.probe_actions(actor, n) for name, (actor, n) in actors.items()}
    for a, b in combinations(actors, 2):
        if actors[a][1] == actors[b][1]:
            print(f"- {a} vs {b}: {np.mean(np.abs(actions[a] - actions[b])):.3f}")
    print(f"\nThe graded protocol (floor: final / do-nothing <= {submission.FLOOR_SHARE}; "
          f"likeness tolerance {submission.LIKENESS_TOLERANCE}):\n")
    print("| actor | done % | mean final distance (m) | doing nothing (m) | final / doing "
          "nothing | nearest shipped actor | own-agent checks | CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    shipped = AGENTS_DIR / "nodes2" / submission.ACTOR_NAME
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        row("shipped nodes2", shipped)

        def one_weight(actor):
            next(actor.net.parameters()).view(-1)[0] += 1e-6

        def scaled(actor):
            for v in actor.net.parameters():
                v.mul_(1.0001)

        row("shipped, one weight + 1e-6", changed_copy(shipped, tmp / "w.pt", one_weight))
        row("shipped, weights x 1.0001", changed_copy(shipped, tmp / "s.pt", scaled))
        for share in args.noise:
            def noisy(actor, share=share):
                generator = torch.Generator().manual_seed(0)
                for v in actor.net.parameters():
                    v.add_(share * v.std() * torch.randn(v.shape, generator=generator))
            row(f"shipped + noise {share:g} x spread", changed_copy(shipped, tmp / "n.pt", noisy))
        zero = fresh_actor(tmp / "zero.pt", 0, 3e-3, None)
        row("doing nothing (output layer 0)", changed_copy(
            zero, zero, lambda actor: [v.zero_() for v in list(actor.net.parameters())[-2:]]))
        for seed in range(args.seeds):
            row(f"untrained, seed {seed}", fresh_actor(tmp / "f.pt", seed, 3e-3, None))
            row(f"untrained, seed {seed}, output init 1", fresh_actor(tmp / "f.pt", seed, 1.0,
                                                                     None))
            row(f"untrained, seed {seed}, recipe scaling, output init 1",
                fresh_actor(tmp / "f.pt", seed, 1.0, shipped))
        for agent in args.agents:
            row(str(agent), agent)


if __name__ == "__main__":
    main()
