"""``dlo-course bench env``: how fast one environment runs, and where a step's time goes.

A benchmark, not a test: these machines are shared, so read the ratios, not the absolute
numbers.
"""

from __future__ import annotations

import time

import numpy as np

from dlo_course.env import make_env
from dlo_course.task import DEFAULT_N_NODES


def time_env(time_mode: str, steps: int, seed: int = 0) -> dict:
    """Run ``steps`` random actions; return actions/s and the share of each part of a step."""
    goals = np.full((1, DEFAULT_N_NODES, 3), 0.5)  # far away: the episode never terminates
    env = make_env(max_episode_steps=None, n_nodes=DEFAULT_N_NODES, goals=goals,
                   time_mode=time_mode)
    try:
        env.reset(seed=seed)
        env.action_space.seed(seed)
        timings = env.unwrapped.scene.timings  # the scene times its own parts
        timings.reset()
        start = time.perf_counter()
        for _ in range(steps):
            env.step(env.action_space.sample())
        wall = time.perf_counter() - start
    finally:
        env.close()
    parts = {"physics": timings.physics, "ik": timings.ik, "read_nodes": timings.read_nodes,
             "observation": timings.observation + timings.other}
    parts["env_overhead"] = wall - sum(parts.values())
    return {"time_mode": time_mode, "steps": steps, "wall_s": wall,
            "actions_per_s": steps / wall,
            "share": {k: v / wall for k, v in parts.items()}}


def bench_env(steps: int = 40, paper_steps: int = 4, seed: int = 0) -> list[dict]:
    """Print actions per second for both time settings and the breakdown of a step."""
    results = [time_env("code", steps, seed), time_env("paper", paper_steps, seed)]
    print(f"{'time mode':<10} {'actions':>7} {'actions/s':>10}   "
          f"{'physics':>8} {'IK':>6} {'nodes':>6} {'obs':>6} {'rest':>6}")
    for r in results:
        s = r["share"]
        print(f"{r['time_mode']:<10} {r['steps']:>7d} {r['actions_per_s']:>10.2f}   "
              f"{s['physics']:>8.1%} {s['ik']:>6.1%} {s['read_nodes']:>6.1%} "
              f"{s['observation']:>6.1%} {s['env_overhead']:>6.1%}")
    ratio = results[0]["actions_per_s"] / results[1]["actions_per_s"]
    print(f"'paper' time costs {ratio:.1f}x the compute of 'code' time per action "
          "(0.06 s vs 0.003 s of physics).")
    return results


def publish(lines: list[str], out=None) -> str:
    """Print a benchmark's result, the command that made it first, and append it to ``out``
    (a path, or None) so that a results file keeps every run with its command."""
    import shlex
    import sys
    from pathlib import Path

    text = "\n".join([f"$ python {shlex.join(sys.argv)}", "", *lines]) + "\n"
    print(text)
    if out is not None:
        with Path(out).open("a") as f:
            f.write(text + "\n")
    return text
