"""Benchmark (not a test): what a Table I episode with reinitialisation costs, rebuilt or forked.

Plays the same test episodes twice in one process with a shipped agent: once rebuilding and
settling the world before every episode (the protocol as written), once settling it once and
running every episode in a forked copy of the process (``dlo_course.snapshot``, the default).
Both give the same episodes bit for bit (checked here too); the ratio of the two times is the
speed-up. Compare ratios from one run: the machines are shared and noisy.

    python benchmarks/evaluation_speed.py [--nodes 4] [--goals small-test] [--episodes 8]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dlo_course.env import make_env
from dlo_course.evaluation import goal_schedule, load_actor, run_traces

RESULTS = Path(__file__).parent / "results" / "evaluation_speed.txt"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=4)
    parser.add_argument("--goals", default="small-test")
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=30)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    actor, n_nodes = load_actor(Path("data/checkpoints") / f"nodes{args.nodes}")
    env = make_env(max_episode_steps=None, n_nodes=n_nodes, goals=args.goals, threshold=0.03)
    # distinct goals, so that no episode is skipped as a repeat
    schedule = goal_schedule(len(env.unwrapped.goal_set), 10 * args.episodes, seed=0)
    keys, episodes = set(), []
    for i, goal in enumerate(schedule):
        key = env.unwrapped.goal_set[goal].tobytes()
        if key not in keys:
            keys.add(key)
            episodes.append(i)
        if len(episodes) == args.episodes:
            break
    seconds, traces = {}, {}
    try:
        for fork in (True, False):
            began = time.perf_counter()
            traces[fork] = run_traces(actor, env, episodes, schedule, True, args.max_steps,
                                      fork=fork)
            seconds[fork] = time.perf_counter() - began
    finally:
        env.close()
    actions = sum(len(t.distances) for t in traces[True])
    lines = [
        f"{args.episodes} test episodes with reinitialisation, {args.nodes} nodes, goals "
        f"{args.goals}, at most {args.max_steps} actions, {actions} actions in all, one process",
        f"rebuilt before every episode: {seconds[False]:.1f} s "
        f"({seconds[False] / args.episodes:.2f} s per episode)",
        f"forked from one settled world: {seconds[True]:.1f} s "
        f"({seconds[True] / args.episodes:.2f} s per episode)",
        f"speed-up: {seconds[False] / seconds[True]:.2f}x; same episodes bit for bit: "
        f"{traces[True] == traces[False]}",
        f"command: python benchmarks/evaluation_speed.py --nodes {args.nodes} --goals "
        f"{args.goals} --episodes {args.episodes} --max-steps {args.max_steps}",
    ]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)


if __name__ == "__main__":
    main()
