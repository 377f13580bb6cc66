"""Compare a recorded small database with the authors' small training file (FACTS.md).

    python benchmarks/database_vs_authors.py [--database small]

FACTS.md gives, for the authors' file and the 4 nodes of rings 26, 23, 18, 15, the mean and
standard deviation of each node's position (world frame, m), and the mean node distance from
the initial shape to the goals (0.234 m). This prints the same statistics for one of our
databases beside them, and the difference in millimetres.
"""

from __future__ import annotations

import argparse

import numpy as np

from dlo_course import load_database
from dlo_course.env import make_env
from dlo_course.mesh import SELECTED_RINGS, selected_nodes

# The authors' small training file, 4 nodes (FACTS.md, "The authors' sweep, move by move").
AUTHORS_MEAN = np.array([[1.135, 0.115, 1.173], [1.114, 0.146, 1.038],
                         [1.096, 0.179, 0.806], [1.096, 0.180, 0.665]])
AUTHORS_STD = np.array([[0.060, 0.136, 0.054], [0.069, 0.136, 0.048],
                        [0.076, 0.131, 0.044], [0.074, 0.122, 0.042]])
AUTHORS_INITIAL_DISTANCE = 0.234


def initial_distances(goals: np.ndarray) -> np.ndarray:
    """(N,) mean node distance from the environment's first observation to each goal."""
    env = make_env(max_episode_steps=None, n_nodes=4, goals=goals)
    try:
        env.reset(seed=0)
        start = env.unwrapped.scene.node_positions()[list(selected_nodes(4))]
    finally:
        env.close()
    return np.linalg.norm(goals - start, axis=2).mean(axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--database", default="small")
    args = parser.parse_args()
    db = load_database(args.database)
    goals = db.goals(4)
    mean, std = goals.mean(axis=0), goals.std(axis=0)
    print(f"database {db.name!r}: {len(db)} records, protocol {db.protocol}")
    print("| ring | ours: mean (x, y, z) ± std (m) | authors' | mean diff (mm) | std diff (mm) |")
    print("|---|---|---|---|---|")
    for i, ring in enumerate(SELECTED_RINGS[4]):
        ours = f"({', '.join(f'{v:.3f}' for v in mean[i])}) ± ({', '.join(f'{v:.3f}' for v in std[i])})"
        theirs = (f"({', '.join(f'{v:.3f}' for v in AUTHORS_MEAN[i])}) ± "
                  f"({', '.join(f'{v:.3f}' for v in AUTHORS_STD[i])})")
        d_mean = ", ".join(f"{1000 * v:+.0f}" for v in mean[i] - AUTHORS_MEAN[i])
        d_std = ", ".join(f"{1000 * v:+.0f}" for v in std[i] - AUTHORS_STD[i])
        print(f"| {ring} | {ours} | {theirs} | {d_mean} | {d_std} |")
    distances = initial_distances(goals)
    print(f"\nmean node distance from the initial shape to the goals: {distances.mean():.3f} m "
          f"(authors': {AUTHORS_INITIAL_DISTANCE} m); within 0.09 m: "
          f"{np.mean(distances < 0.09):.0%} (authors': 10%)")


if __name__ == "__main__":
    main()
