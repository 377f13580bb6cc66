"""Benchmark (not a test): how many test goals a policy that does nothing already meets.

With reinitialisation every test episode starts from the same initial shape. A goal whose
mean node distance from that shape is already below the threshold is met by any first action
that does not make things worse, so the share of such goals is a floor under Table I's done %
that says nothing about learning. The paper's test goals (`small-test`, `large-test`) are
mostly the sweep's first, uncompressed level (FACTS.md), so on the small box the floor is high.

    python benchmarks/test_goal_floor.py [--episodes 100] [--seed 0]

Prints, per node count and goal source, the share of goals within 0.05 m and 0.03 m of the
initial shape: over the whole goal list (the paper's test files, repeats included) and over
the episodes `dlo-course reproduce` draws (the same goal schedule).
"""

from __future__ import annotations

import argparse

import numpy as np

from dlo_course.database import resolve_goals
from dlo_course.env import DLOShapeEnv, mean_node_distance
from dlo_course.evaluation import goal_schedule

SOURCES = ("small-test", "large-test", "small", "large")
THRESHOLDS = (0.05, 0.03)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print("| nodes | goals | " + " | ".join(f"within {t} m: all goals | {args.episodes} episodes"
                                           for t in THRESHOLDS) + " |")
    print("|---|---|" + "---|---|" * len(THRESHOLDS))
    for n in (2, 4, 6):
        env = DLOShapeEnv(n_nodes=n)
        try:
            env.reset(seed=args.seed, options={"reinitialize": True})
            start = env.unwrapped.scene.node_positions()[env.unwrapped.node_ids]
        finally:
            env.close()
        for source in SOURCES:
            goals = resolve_goals(source, n)
            distance = np.array([mean_node_distance(start, g) for g in goals])
            drawn = distance[goal_schedule(len(goals), args.episodes, args.seed)]
            cells = [f"{np.mean(distance < t):.1%} | {np.mean(drawn < t):.0%}"
                     for t in THRESHOLDS]
            print(f"| {n} | {source} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
