"""Benchmark (not a test): the course's scene against the authors' code's settings, for
everything that simulates, and the authors' settings' database against the authors' file.

"course" is today's default ``SimParams()`` (edge dampers, both ends anchored where they are,
no rod-plane or rod-gripper contact); "authors" is ``SimParams(**AUTHORS_SETTINGS)`` (no
dampers, node 0 anchored to the plane body, every contact on, fingers open). Each part runs
both scenes in the same process or back to back, so the ratio, not the rate, is what to
read on a shared machine:

* env: ``DLOShape-v0`` (4 nodes) stepped with the same seeded random actions, in interleaved
  blocks, with a reset (rebuilding the world) every 30 actions;
* sweep: the first ``--sweep-records`` records of the authors' sweep of the small box, timed;
  with all 930, the per-node statistics of each scene's records beside the authors' file's
  (FACTS.md), as ``benchmarks/database_vs_authors.py`` prints them;
* train: ``mpiexec -n 2 dlo-course train --preset recipe`` for a few short episodes, the
  scene passed as ``--env-kwargs '{"params": {...}}'``, transitions per second after the
  first episode, the two scenes alternating twice.

    python benchmarks/scene_authors_settings.py [--actions 120] [--sweep-records 930]
        [--train-episodes 3] [--train-steps 60] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dlo_course.database import BOXES, _record_authors_sweep
from dlo_course.env import make_env
from dlo_course.simulation import AUTHORS_SETTINGS, RodScene, SimParams

sys.path.insert(0, str(Path(__file__).parent))
from database_vs_authors import AUTHORS_MEAN, AUTHORS_STD  # noqa: E402  (sibling scripts)
from dlo_train_throughput import run  # noqa: E402

SCENES = {"course": {}, "authors": dict(AUTHORS_SETTINGS)}


def env_rates(actions: int, block: int = 10, reset_every: int = 30, seed: int = 0) -> dict:
    """Actions per second (resets included) of each scene, interleaved blocks."""
    envs = {name: make_env(max_episode_steps=None, n_nodes=4, params=kw)
            for name, kw in SCENES.items()}
    moves = np.random.default_rng(seed).uniform(-1, 1, size=(actions, 3)).astype(np.float32)
    seconds = dict.fromkeys(envs, 0.0)
    try:
        for env in envs.values():
            env.reset(seed=seed)
        for b, start in enumerate(range(0, actions, block)):
            names = list(envs)[b % 2:] + list(envs)[:b % 2]  # alternate who goes first
            for name in names:
                env = envs[name]
                t = time.perf_counter()
                for i in range(start, min(start + block, actions)):
                    if i and i % reset_every == 0:
                        env.reset(options={"reinitialize": True})
                    env.step(moves[i])
                seconds[name] += time.perf_counter() - t
    finally:
        for env in envs.values():
            env.close()
    return {name: actions / s for name, s in seconds.items()}


def sweep(records: int) -> dict:
    """Seconds to record the first ``records`` of the small box's sweep, and the records'
    selected nodes (records, 4, 3), for each scene."""
    from dlo_course.mesh import selected_nodes

    out = {}
    for name, kw in SCENES.items():
        scene = RodScene(SimParams(**kw))
        nodes = []
        t = time.perf_counter()
        _record_authors_sweep(scene, BOXES["small"], records,
                              lambda before, dt: nodes.append(scene.node_positions()))
        out[name] = (time.perf_counter() - t, np.array(nodes)[:, list(selected_nodes(4))])
        scene.close()
    return out


def train_rate(kw: dict, episodes: int, steps: int, out: Path) -> float:
    """Transitions per second (all ranks) of a short recipe run on 2 ranks in scene ``kw``."""
    return run(2, episodes, steps, out, preset="recipe",
               extra=("--env-kwargs", json.dumps({"params": kw})))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actions", type=int, default=120)
    parser.add_argument("--sweep-records", type=int, default=930)
    parser.add_argument("--train-episodes", type=int, default=3)
    parser.add_argument("--train-steps", type=int, default=60)
    parser.add_argument("--out", type=Path, default=None, help="also write the output here")
    args = parser.parse_args()
    lines = [time.strftime("%a %b %d %H:%M:%S UTC %Y", time.gmtime()),
             "$ python " + " ".join(shlex.quote(a) for a in sys.argv), ""]

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    say(f"{'what':<44} {'course':>10} {'authors':>10} {'authors/course speed':>21}")
    rates = env_rates(args.actions)
    c, a = rates.values()
    say(f"{'env: actions/s (4 nodes, reset every 30)':<44} {c:>10.2f} {a:>10.2f} {a / c:>20.2f}x")
    swept = sweep(args.sweep_records)
    (c, course_nodes), (a, authors_nodes) = swept.values()
    say(f"{f'sweep: s for {args.sweep_records} small-box records':<44} {c:>10.1f} {a:>10.1f} "
        f"{c / a:>20.2f}x")
    with tempfile.TemporaryDirectory() as tmp:
        train = {name: [] for name in SCENES}
        for round_ in range(2):
            for i, (name, kw) in enumerate(SCENES.items()):
                train[name].append(train_rate(kw, args.train_episodes, args.train_steps,
                                              Path(tmp) / f"r{round_}_{i}"))
    c, a = (float(np.mean(v)) for v in train.values())
    say(f"{'train: transitions/s, recipe, 2 ranks':<44} {c:>10.2f} {a:>10.2f} {a / c:>20.2f}x")
    if args.sweep_records >= 930:
        say("\nper-node mean and spread minus the authors' small file's (mm, x y z), rings "
            "26, 23, 18, 15:")
        for name, nodes in (("course", course_nodes), ("authors", authors_nodes)):
            d_mean = np.round((nodes.mean(0) - AUTHORS_MEAN) * 1e3).astype(int).tolist()
            d_std = np.round((nodes.std(0) - AUTHORS_STD) * 1e3).astype(int).tolist()
            say(f"  {name:<8} mean {d_mean}\n  {'':<8} std  {d_std}")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
