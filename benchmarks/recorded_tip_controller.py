"""Yardstick for Table I: the privileged recorded-tip controller under the test protocol.

    python benchmarks/recorded_tip_controller.py --nodes 4 --database small --episodes 12

It knows which database goal it is given and drives the tip straight to where the tip was when
that goal was recorded (``dlo_course.evaluation.recorded_tip_controller``). If the tip position
alone fixed the rod's shape, it would reach nearly every goal.
"""

import argparse

from dlo_course import load_database
from dlo_course.env import make_env
from dlo_course.evaluation import goal_schedule, recorded_tip_controller, run_episodes, summarize


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=4, choices=(2, 4, 6))
    parser.add_argument("--database", default="small", choices=("small", "large"))
    parser.add_argument("--episodes", type=int, default=12)
    parser.add_argument("--max-steps", type=int, default=30)
    parser.add_argument("--threshold", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    db = load_database(args.database)
    env = make_env(max_episode_steps=None, n_nodes=args.nodes, goals=args.database,
                   threshold=args.threshold)
    try:
        schedule = goal_schedule(len(db.tip), args.episodes, args.seed)
        records = run_episodes(recorded_tip_controller(db, args.nodes), env,
                               range(args.episodes), schedule, True, args.max_steps)
    finally:
        env.close()
    s = summarize(records)
    print(f"recorded-tip controller, {args.nodes} nodes, {args.database} goals, threshold "
          f"{args.threshold} m, {s.episodes} episodes of at most {args.max_steps} actions "
          f"(with reinitialization, seed {args.seed}):")
    print(f"done {s.done_percent:.1f}% (95% CI {s.done_ci_low:.1f}-{s.done_ci_high:.1f}), final "
          f"distance {s.mean_distance:.3f} +- {s.std_distance:.3f} m, best {s.best_distance:.3f} m")


if __name__ == "__main__":
    main()
