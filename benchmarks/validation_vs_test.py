"""Benchmark (not a test): does validation rank agents as the test does?

An agent is chosen to ship on validation goals, which must not be the test goals. Two
validations, for every agent of one node count that ``benchmarks/seeds_table1.py run`` tested
in today's scene (every agent of a ``nodesN_scene35*_runs.json`` manifest):

* ``uniform``: 100 episodes on goals drawn uniformly among the small database's records that
  are not test goals (``seeds_table1.py validate``, cached there; issue 36 chose with it);
* ``like-test``: ``--episodes`` (200) episodes on held-out records drawn with the test's mix
  of sweep levels (:meth:`dlo_course.database.Database.held_out_indices`): the test goals
  come mostly from the first level, the held-out records mostly from the compressed ones.

Both follow Table I's protocol (reinitialisation, at most 30 actions, goal draw seed 7) and
score the done % at 0.05 and 0.03 m and the mean final distance at 0.03 m. Each is set
against the test (the small database's test goals with reinitialisation, 100 episodes: the
cells validation can predict, drawn from the same database) by Spearman's rank correlation
over the agents (:func:`dlo_course.evaluation.rank_correlation`), and the report says which
agent each validation would ship and what that agent scores on the test.

    mpiexec -n 2 python benchmarks/validation_vs_test.py run --nodes 4
    python benchmarks/validation_vs_test.py report

``run`` validates (and caches, under the actor's digest) every agent still missing;
``report`` writes ``benchmarks/results/seeds/validation_vs_test.md`` from the cache.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from dlo_course import mpi
from dlo_course.database import load_database
from dlo_course.evaluation import Summary, evaluate_thresholds, rank_correlation
from dlo_course.paths import REPO_ROOT
from dlo_course.reproduce import actor_digest
from dlo_course.task import TABLE_THRESHOLDS

sys.path.insert(0, str(Path(__file__).parent))
from seeds_table1 import (CACHE, EPISODES as TEST_EPISODES, MAX_STEPS, RESULTS,  # noqa: E402
                          VALIDATION_SEED)

LIKE_TEST_EPISODES = 200
OUT = RESULTS / "validation_vs_test.md"
STRICT, LOOSE = min(TABLE_THRESHOLDS), max(TABLE_THRESHOLDS)


def _read(path: Path) -> dict[float, Summary] | None:
    if not path.is_file():
        return None
    blob = json.loads(path.read_text())
    blob = blob.get("summaries", blob)  # test runs keep their minutes beside the summaries
    return {float(t): Summary(**row) for t, row in blob.items()}


def test_file(nodes: int, digest: str, database: str = "small") -> Path:
    """The seeds' cached Table I run with reinitialisation on ``database``'s test goals."""
    return CACHE / (f"test_with_n{nodes}_{database}_t0.05-0.03_e{TEST_EPISODES}_s{MAX_STEPS}_"
                    f"seed0_code_{digest}.json")


def uniform_file(nodes: int, digest: str) -> Path:
    """``seeds_table1.py validate``'s cached validation (uniform over held-out records)."""
    return CACHE / f"validation_n{nodes}_e100_s{MAX_STEPS}_seed{VALIDATION_SEED}_{digest}.json"


def like_test_file(nodes: int, digest: str, episodes: int) -> Path:
    return CACHE / (f"validation-like-test_n{nodes}_e{episodes}_s{MAX_STEPS}_"
                    f"seed{VALIDATION_SEED}_{digest}.json")


def agents(nodes: int) -> dict[str, Path]:
    """{label: folder} of every agent for ``nodes`` that ``seeds_table1.py run`` tested in
    today's scene (issue 35's: its variants are named ``scene35...``), one per actor."""
    found: dict[str, tuple[str, Path]] = {}
    for manifest in sorted(RESULTS.glob(f"nodes{nodes}_scene35*_runs.json")):
        for key, entry in json.loads(manifest.read_text()).items():
            if key == "what":
                continue
            folder = REPO_ROOT / entry["agent"]
            digest = actor_digest(folder)
            if test_file(nodes, digest).is_file() and digest not in found:
                found[digest] = (folder.name, folder)
    return dict(found.values())


def like_test_validation(nodes: int, folder: Path, episodes: int) -> dict[float, Summary]:
    """One agent's like-test validation, cached (every rank must call it)."""
    saved = like_test_file(nodes, actor_digest(folder), episodes)
    if not saved.is_file():
        database = load_database("small")
        goals = database.goals(nodes)[database.held_out_indices(nodes, size=episodes,
                                                                 seed=VALIDATION_SEED)]
        results = evaluate_thresholds(folder, goals, TABLE_THRESHOLDS, reinitialize=True,
                                      episodes=episodes, max_steps=MAX_STEPS,
                                      seed=VALIDATION_SEED, n_nodes=nodes,
                                      show_progress=mpi.is_root())
        if mpi.is_root():
            CACHE.mkdir(parents=True, exist_ok=True)
            saved.write_text(json.dumps({str(t): results[t][0].as_dict()
                                         for t in TABLE_THRESHOLDS}, indent=1) + "\n")
        mpi.barrier()
    return _read(saved)


def run(nodes: int, episodes: int) -> None:
    for label, folder in agents(nodes).items():
        if mpi.is_root():
            print(f"{nodes} nodes, {label}: like-test validation, {episodes} episodes",
                  flush=True)
        like_test_validation(nodes, folder, episodes)


def _score(summaries: dict[float, Summary]) -> float:
    """The done % averaged over both thresholds: what Table I reports, in one number."""
    return (summaries[LOOSE].done_percent + summaries[STRICT].done_percent) / 2


def _cell(s: dict[float, Summary] | None) -> str:
    if s is None:
        return "-"
    return (f"{s[LOOSE].done_percent:.0f} / {s[STRICT].done_percent:.0f} / "
            f"{100 * s[STRICT].mean_distance:.2f}")


def report(episodes: int) -> str:
    lines = ["# Does validation rank agents as the test does?", "",
             "Made by `mpiexec -n 2 python benchmarks/validation_vs_test.py run --nodes N` "
             "(N = 2, 4, 6) and `python benchmarks/validation_vs_test.py report`; the method is "
             "in the script's docstring. Each cell: done % at 0.05 m / done % at 0.03 m / "
             "mean final distance at 0.03 m (cm). Test: the small database's test goals "
             f"with reinitialisation, {TEST_EPISODES} episodes. Validation on held-out "
             f"records only: `uniform` ({100} episodes, uniform over them) and `like-test` "
             f"({episodes} episodes, the test's mix of sweep levels).", "",
             "Spearman's rank correlation between a validation's score and the test's (the "
             "done % averaged over both thresholds; for the mean distance, lower is better, "
             "so its sign is flipped): 1 ranks as the test does, 0 is a random pick. Which "
             "agent a validation ships: the best score, a tie broken by the smaller mean final "
             "distance at 0.03 m.", ""]
    summary = ["| nodes | agents | ρ uniform (done %) | ρ like-test (done %) | "
               "ρ like-test (mean distance) | uniform ships (test score) | "
               "like-test ships (test score) | best on the test (test score) |",
               "|---|---|---|---|---|---|---|---|"]
    tables = []
    for nodes in (2, 4, 6):
        rows = []
        for label, folder in agents(nodes).items():
            digest = actor_digest(folder)
            rows.append((label, _read(test_file(nodes, digest)),
                         _read(uniform_file(nodes, digest)),
                         _read(like_test_file(nodes, digest, episodes))))
        rows = [r for r in rows if r[3] is not None]  # validated like-test
        if len(rows) < 3:
            continue
        test = np.array([_score(r[1]) for r in rows])
        like = np.array([_score(r[3]) for r in rows])
        like_distance = np.array([-r[3][STRICT].mean_distance for r in rows])
        both = [i for i, r in enumerate(rows) if r[2] is not None]
        uniform = np.array([_score(rows[i][2]) for i in both])
        rho_uniform = rank_correlation(uniform, test[both]) if len(both) >= 3 else float("nan")

        def ships(scores, among, distances):
            # The best score ships; a tie goes to the smaller mean final distance at 0.03 m.
            pick = among[max(range(len(among)), key=lambda i: (scores[i], distances[i]))]
            return f"{rows[pick][0]} ({test[pick]:.1f})"

        uniform_distance = [-rows[i][2][STRICT].mean_distance for i in both]
        test_distance = [-r[1][STRICT].mean_distance for r in rows]

        summary.append(
            f"| {nodes} | {len(rows)} | "
            + (f"{rho_uniform:+.2f} ({len(both)} agents)" if len(both) >= 3 else "-")
            + f" | {rank_correlation(like, test):+.2f} | "
              f"{rank_correlation(like_distance, test):+.2f} | "
            + (ships(uniform, both, uniform_distance) if both else "-")
            + f" | {ships(like, list(range(len(rows))), like_distance)} | "
              f"{ships(test, list(range(len(rows))), test_distance)} |")
        tables += [f"## {nodes} nodes", "",
                   "| agent | test (small, with reinit.) | validation: uniform | "
                   "validation: like-test |", "|---|---|---|---|"]
        tables += [f"| {label} | {_cell(t)} | {_cell(u)} | {_cell(v)} |"
                   for label, t, u, v in rows]
        tables.append("")
    text = "\n".join(lines + summary + [""] + tables)
    OUT.write_text(text)
    print(text)
    return text


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("run", "report"))
    parser.add_argument("--nodes", type=int, choices=(2, 4, 6), help="run: the node count")
    parser.add_argument("--episodes", type=int, default=LIKE_TEST_EPISODES,
                        help="like-test validation episodes per agent")
    args = parser.parse_args(argv)
    if args.command == "run":
        if args.nodes is None:
            parser.error("run wants --nodes")
        run(args.nodes, args.episodes)
    elif mpi.is_root():
        report(args.episodes)


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    main(sys.argv[1:])
