"""Two versions of the course, one interleaved run: environment steps, a sweep, training.

    git worktree add /tmp/before 214f89c      # the version to compare with
    python benchmarks/scene_before_after.py --before /tmp/before [--rounds 3] [--out FILE]

Each measurement runs in a fresh process whose ``PYTHONPATH`` puts one version's
``dlo_course`` first, and the two versions take turns (the order alternating between rounds),
so that a change of the machine's load falls on both: read the ratios, not the rates.

* env: ``DLOShape-v0`` (4 nodes), ``--env-steps`` random actions after a reset, actions/s;
* sweep: the first ``--sweep-records`` records of the small box's authors' sweep, records/s;
* train: ``dlo-course train --preset smoke`` on 2 MPI ranks, transitions/s of both ranks
  after the first episode (``--train-episodes`` episodes of ``--train-steps`` actions).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from dlo_course.bench import publish

HERE = Path(__file__).resolve().parent.parent

ENV_SNIPPET = """
import json, sys, time
import numpy as np
from dlo_course.env import make_env
steps = int(sys.argv[1])
env = make_env(max_episode_steps=None, n_nodes=4, goals=np.full((1, 4, 3), 0.5))
env.reset(seed=0)
env.action_space.seed(0)
start = time.perf_counter()
for _ in range(steps):
    env.step(env.action_space.sample())
print(json.dumps({"rate": steps / (time.perf_counter() - start)}))
"""

SWEEP_SNIPPET = """
import json, sys, tempfile, time
from pathlib import Path
from dlo_course.database import generate_database
records = int(sys.argv[1])
with tempfile.TemporaryDirectory() as tmp:
    start = time.perf_counter()
    generate_database("small", out=Path(tmp) / "s.npz", limit=records, progress=False)
    print(json.dumps({"rate": records / (time.perf_counter() - start)}))
"""

TRAIN_SNIPPET = """
import json, subprocess, sys, tempfile
from pathlib import Path
from dlo_course.rundir import read_progress
episodes, steps = sys.argv[1], sys.argv[2]
with tempfile.TemporaryDirectory() as tmp:
    out = Path(tmp) / "run"
    mpiexec = Path(sys.executable).parent / "mpiexec"
    subprocess.run([str(mpiexec), "-n", "2", sys.executable, "-m", "dlo_course.cli", "train",
                    "--preset", "smoke", "--nodes", "4", "--episodes", episodes,
                    "--steps-per-episode", steps, "--out", str(out), "--no-progress"],
                   check=True, capture_output=True)
    progress = read_progress(out)
    t, n = progress["wall_time"], progress["transitions"]
    print(json.dumps({"rate": float((n[-1] - n[0]) / (t[-1] - t[0]))}))
"""


def measure(tree: Path, snippet: str, *args: object) -> float:
    """Run ``snippet`` with ``tree``'s dlo_course first on the path; return its rate."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run([sys.executable, "-c", snippet, *map(str, args)], env=env, cwd=tree,
                          check=True, capture_output=True, text=True)
    return float(json.loads(done.stdout.strip().splitlines()[-1])["rate"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="the older checkout")
    parser.add_argument("--after", type=Path, default=HERE, help="default: this checkout")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--env-steps", type=int, default=60)
    parser.add_argument("--sweep-records", type=int, default=60)
    parser.add_argument("--train-episodes", type=int, default=3)
    parser.add_argument("--train-steps", type=int, default=60)
    parser.add_argument("--no-train", action="store_true", help="skip the training part")
    parser.add_argument("--only-train", action="store_true", help="only the training part")
    parser.add_argument("--out", type=Path, default=None, help="append the result here")
    args = parser.parse_args()
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    parts = {} if args.only_train else {"env (actions/s)": (ENV_SNIPPET, args.env_steps),
                                        "sweep (records/s)": (SWEEP_SNIPPET, args.sweep_records)}
    if not args.no_train:
        parts["train, 2 ranks (transitions/s)"] = (TRAIN_SNIPPET, args.train_episodes,
                                                  args.train_steps)
    rates = {(part, name): [] for part in parts for name in trees}
    for r in range(args.rounds):
        for part, (snippet, *extra) in parts.items():
            order = list(trees) if r % 2 == 0 else list(trees)[::-1]
            for name in order:
                rates[(part, name)].append(measure(trees[name], snippet, *extra))
                print(f"round {r + 1} {part} {name}: {rates[(part, name)][-1]:.2f}",
                      file=sys.stderr)
    lines = [f"before: {trees['before']}, after: {trees['after']}; {args.rounds} interleaved "
             "rounds, mean rate (per round)", "",
             "| part | before | after | after / before |", "|---|---|---|---|"]
    for part in parts:
        b, a = np.array(rates[(part, "before")]), np.array(rates[(part, "after")])
        lines.append(f"| {part} | {b.mean():.2f} ({', '.join(f'{v:.2f}' for v in b)}) | "
                     f"{a.mean():.2f} ({', '.join(f'{v:.2f}' for v in a)}) | "
                     f"{a.mean() / b.mean():.2f} |")
    publish(lines, args.out)


if __name__ == "__main__":
    main()
