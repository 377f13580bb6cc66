"""Benchmark (not a test): where the minutes of `dlo-course reproduce` go, from its kept runs.

`dlo-course reproduce` keeps every finished evaluation run in OUT/runs/ with the minutes it
took. This script reads the runs of the agents in AGENTS (by their actors' digests, as
reproduce names them), recomputes for each run how many episodes were simulated (with
reinitialisation a repeated goal is simulated once per rank and the world is settled once,
then forked; without, every episode resets the world, 12 + m physics steps) and how many
physics steps they cost (the actions, taken from the run's mean steps per episode, plus the
resets), and prints minutes, steps and steps per second per protocol. Nothing is simulated:
it takes seconds.

    python benchmarks/reproduction_time.py [--runs docs/reproduction/runs] [--agents data/checkpoints]

The physics steps are the floor of the cost: one action or one reset step is one
`stepSimulation()` of 3 ms in 20 sub-steps (about 99% of an action's time, `dlo-course bench
env`), so a protocol's minutes can only shrink by simulating fewer steps or cheaper ones.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dlo_course.database import resolve_goals
from dlo_course.evaluation import goal_schedule
from dlo_course.reproduce import _policy
from dlo_course.simulation import SimParams

RANKS = 2  # the runs kept in the repository were made on 2 ranks


def simulated_episodes(database: str, protocol: str, n_nodes: int, episodes: int,
                       seed: int, reinit: bool) -> int:
    """Episodes actually simulated: with reinitialisation, distinct goals per rank."""
    if not reinit:
        return episodes
    goals = resolve_goals(f"{database}-test" if protocol == "test" else database, n_nodes)
    schedule = goal_schedule(len(goals), episodes, seed)
    return sum(len({goals[int(schedule[e])].tobytes() for e in range(r, episodes, RANKS)})
               for r in range(RANKS))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=Path("docs/reproduction/runs"))
    parser.add_argument("--agents", type=Path, default=Path("data/checkpoints"))
    args = parser.parse_args()

    # the digest that names an agent's kept runs, as reproduce computes it
    digests = {n: _policy(args.agents, None, n)[1] for n in (2, 4, 6)}
    totals: dict[str, list[float]] = {}
    print(f"{'run':<48} {'min':>6} {'episodes':>8} {'simulated':>9} {'actions':>7} "
          f"{'resets':>6} {'steps/s':>7}")
    for path in sorted(args.runs.glob("*.json")):
        # e.g. test_with_n4_small_t0.05-0.03_e100_s30_seed0_code_<digest>.json
        parts = path.stem.split("_")
        if parts[0] not in ("test", "whole") or parts[-1] not in digests.values():
            continue  # a controller's run, or an agent no longer shipped
        protocol, reinit, nodes, database = parts[0], parts[1] == "with", int(parts[2][1:]), parts[3]
        if digests[nodes] != parts[-1]:
            continue
        episodes = int(parts[5][1:])
        seed = int(parts[7][len("seed"):])
        run = json.loads(path.read_text())
        # the smallest threshold's summary: with reinitialisation the run played at it
        strictest = min(run["summaries"], key=float)
        mean_steps = run["summaries"][strictest]["mean_steps"]
        simulated = simulated_episodes(database, protocol, nodes, episodes, seed, reinit)
        actions = simulated * mean_steps
        resets = 0 if reinit else episodes * SimParams().reset_steps(nodes, rebuilt=False)
        steps = actions + resets
        seconds = run["minutes"] * 60
        print(f"{path.stem[:48]:<48} {run['minutes']:6.1f} {episodes:8d} {simulated:9d} "
              f"{actions:7.0f} {resets:6d} {steps / seconds:7.1f}")
        key = f"{protocol} goals, {'with' if reinit else 'without'} reinitialisation"
        t = totals.setdefault(key, [0, 0.0, 0.0, 0.0])
        t[0] += 1
        t[1] += run["minutes"]
        t[2] += actions
        t[3] += resets
    print()
    print(f"{'protocol':<45} {'runs':>4} {'minutes':>7} {'actions':>8} {'reset steps':>11} "
          f"{'steps/s':>7}")
    all_minutes = all_steps = 0.0
    for key, (runs, minutes, actions, resets) in totals.items():
        print(f"{key:<45} {runs:4d} {minutes:7.1f} {actions:8.0f} {resets:11.0f} "
              f"{(actions + resets) / (minutes * 60):7.1f}")
        all_minutes += minutes
        all_steps += actions + resets
    if all_minutes:
        print(f"{'all':<45} {'':4} {all_minutes:7.1f} {'':8} {all_steps:11.0f} "
              f"{all_steps / (all_minutes * 60):7.1f}  (physics steps in all, "
              f"{RANKS} ranks)")


if __name__ == "__main__":
    main()
