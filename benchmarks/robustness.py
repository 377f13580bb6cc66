"""Benchmark (not a test): how the shipped 4-node agent, and optionally the Jacobian
controller, cope with a world that is not the one they were trained in (lesson 16).

Each setting is the paper's protocol with reinitialisation on its small test goals
("small-test", goal draw seed 0: the same goals in every setting, at most 30 actions), in a
world changed in one way (:mod:`dlo_course.robustness`): the rod's Young's modulus, mass or
damping scaled by a factor, or Gaussian noise on the observed node positions P_c. The
unperturbed setting (every factor 1, no noise) is run once and joins every curve.

    python benchmarks/robustness.py [--episodes 20] [--factors 0.7,1.0,1.3]
        [--parameters youngs_modulus,mass,damping] [--noise 0,0.005,0.01] [--jacobian]
        [--no-agent]
        [--out benchmarks/results/robustness]

Writes one JSON per setting into --out (``CONTROLLER_PARAMETER_VALUE.json``), skipping the
settings whose JSON is already there with the same episodes (a stopped run resumes), then
``results.md`` (the table, and each change's paired difference from the training world,
:func:`dlo_course.robustness.changes_table`) and ``robustness.png`` (done % at 0.05 m against
each change, with Wilson 95% intervals).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dlo_course import mpi, robustness
from dlo_course.paths import DATA_DIR


def floats(text: str) -> list[float]:
    return [float(part) for part in text.split(",") if part.strip()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--factors", type=floats, default=[0.7, 1.0, 1.3],
                        help="comma-separated factors of every parameter (1 = training)")
    parser.add_argument("--parameters", default="youngs_modulus,mass,damping",
                        help=f"comma-separated, among {', '.join(robustness.PERTURBABLE)}")
    parser.add_argument("--noise", type=floats, default=[0.0, 0.005, 0.01],
                        help="comma-separated noise std on P_c (m)")
    parser.add_argument("--agent", type=Path, default=DATA_DIR / "checkpoints" / "nodes4")
    parser.add_argument("--jacobian", action="store_true",
                        help="also evaluate the Jacobian controller (dlo_course.jacobian)")
    parser.add_argument("--no-agent", action="store_true",
                        help="skip the trained agent (e.g. to run the Jacobian controller "
                             "alone, with its own --episodes)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/robustness"))
    args = parser.parse_args()

    parameters = [p.strip() for p in args.parameters.split(",") if p.strip()]
    for name in parameters:
        robustness.validate_factors({name: 1.0})
    settings = [(robustness.NOMINAL, 1.0)]
    settings += [(name, f) for name in parameters for f in args.factors if f != 1.0]
    settings += [(robustness.NOISE, s) for s in args.noise if s != 0.0]
    controllers = [] if args.no_agent else [(args.agent.name, args.agent)]
    if args.jacobian:
        from dlo_course.jacobian import CONTROLLERS

        controllers.append(("jacobian", CONTROLLERS["jacobian"](4)))

    for label, agent in controllers:
        for parameter, value in settings:
            path = robustness.setting_file(args.out, label, parameter, value)
            start = time.perf_counter()
            record = robustness.run_setting(agent, label, parameter, value, args.out,
                                            episodes=args.episodes, seed=args.seed,
                                            show_progress=False)
            took = time.perf_counter() - start
            if mpi.rank() != 0:
                continue  # it played its share of the episodes; rank 0 reports
            s = record["summaries"]["0.05"]
            print(f"{path.name}: done {s['done_percent']:.0f}% at 0.05 m "
                  f"({s['done_ci_low']:.0f}-{s['done_ci_high']:.0f}), "
                  f"{record['wall_seconds']} s when run, {took:.0f} s now", flush=True)

    if mpi.rank() != 0:
        return
    results = robustness.load_results(args.out)
    text = robustness.results_table(results) + "\n"
    if all(r.get("records") for r in results):  # files written before 2026-12-07 kept none
        for threshold in robustness.TABLE_THRESHOLDS:
            text += (f"\nEach change against the training world on the same episodes (the "
                     f"same goals), at {threshold:g} m:\n\n"
                     + robustness.changes_table(results, threshold) + "\n")
    (args.out / "results.md").write_text(text)
    robustness.plot_results(results, args.out / "robustness.png")
    print(f"wrote {args.out / 'results.md'} and {args.out / 'robustness.png'}")


if __name__ == "__main__":
    import matplotlib

    matplotlib.use("Agg")
    main()
