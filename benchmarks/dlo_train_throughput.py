"""Benchmark (not a test): training throughput on the rod with 1 and 2 MPI ranks.

Runs the real trainer (`dlo-course train`) on DLOShape-v0 (4 nodes) for a few short episodes
with 1 and then 2 ranks, and prints transitions per second of all agents together, after the
first episode (start-up and warm-up excluded). Run it on an otherwise idle machine: the ratio
of the two rates is what to read.

    python benchmarks/dlo_train_throughput.py [--episodes 3] [--steps 100]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from dlo_course.rundir import read_progress


def run(n_ranks: int, episodes: int, steps: int, out: Path, preset: str = "smoke",
        extra: tuple[str, ...] = ()) -> float:
    """Transitions per second of all ranks after the first episode of a short training run."""
    mpiexec = Path(sys.executable).parent / "mpiexec"
    cmd = [str(mpiexec), "-n", str(n_ranks), sys.executable, "-m", "dlo_course.cli", "train",
           "--preset", preset, "--nodes", "4", "--episodes", str(episodes),
           "--steps-per-episode", str(steps), "--out", str(out), "--no-progress", *extra]
    subprocess.run(cmd, check=True, capture_output=True)
    progress = read_progress(out)
    t, n = progress["wall_time"], progress["transitions"]
    return float((n[-1] - n[0]) / (t[-1] - t[0]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--steps", type=int, default=100)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rates = {n: run(n, args.episodes, args.steps, Path(tmp) / f"ranks{n}") for n in (1, 2)}
    for n, rate in rates.items():
        print(f"{n} rank(s): {rate:.2f} transitions/s (all agents, one update per step)")
    print(f"2 ranks / 1 rank: {rates[2] / rates[1]:.2f}x")


if __name__ == "__main__":
    main()
