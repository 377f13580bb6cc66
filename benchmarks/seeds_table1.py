"""Benchmark (not a test): how much of Table I is luck. One configuration, several training seeds.

Each shipped agent is one training seed. This script evaluates several agents trained with the
same configuration and different ``--seed`` on Table I's cells *with reinitialisation* (both
databases' test goals, 0.05 m and 0.03 m), and with ``--without`` on the cells without
reinitialisation too (left out by default: on the paper's test goals they took 46.2 minutes of
2 ranks against 13.2 for the cells with, for the three node counts,
benchmarks/results/reproduction_time.txt), then reports per cell:

* per seed: done % over the episodes with its Wilson interval (the episodes' luck);
* over seeds: the mean done % and its 95% t-interval (the training's luck,
  :func:`dlo_course.evaluation.seed_interval`), and the Wilson interval of all seeds' episodes
  pooled, beside the paper's number. The verdict takes the union of the two intervals: with
  few seeds that agree, the t-interval is narrower than the episodes allow (zero wide when
  two seeds score the same), and with seeds that disagree, the pooled episodes hide it (every
  seed plays the same goals, so pooling does not sample more goals).

    mpiexec -n 2 python benchmarks/seeds_table1.py run --nodes 6 \\
        --agent 0=data/checkpoints/seeds/nodes6_seed0 --agent 1=data/checkpoints/seeds/nodes6_seed1 ...
    python benchmarks/seeds_table1.py report --nodes 6
    python benchmarks/seeds_table1.py table --use 2=VARIANT --use 4=VARIANT --use 6=VARIANT
    mpiexec -n 2 python benchmarks/seeds_table1.py validate --nodes 6 --agent 0=... ...

``validate`` says which seed to ship without looking at the test goals: Table I's protocol
(with reinitialisation, 100 episodes, at most 30 actions) on the small database's records
that are not among the paper's test goals (goal draw seed 7), scored at 0.03 m, ties broken
at 0.05 m and then by the mean final distance; it writes ``nodesN[_VARIANT]_validation.md``.
Its candidates may differ by a lever as well as by the seed, so each ``--agent`` takes any
plain label (``--agent sigma0.3-seed1=FOLDER``); each agent's validation is cached under its
actor's digest, so adding a candidate later costs only that candidate.

The 6-node seeds were trained with the then shipped 6-node agent's configuration
(data/checkpoints/seeds/nodes6_seed0/config.json), changing only the seed; a stopped run
resumes with ``--resume`` added:

    mpiexec -n 2 dlo-course train --preset recipe --nodes 6 --env-kwargs '{"threshold": 0.05}' \
        --stop-at-goal --validate-every 0 --episodes 130 --seed S --out runs/recipe_n6_sS
    dlo-course ship runs/recipe_n6_sS data/checkpoints/seeds/nodes6_seedS

A variant (one lever changed) is trained the same way with its flag and its own --out, and
evaluated with ``--variant NAME`` (results in ``nodesN_NAME.*``). The first, OU sigma 0.3
(the paper's) instead of 0.15, seed S (seed 0 is in data/checkpoints/seeds/):

    mpiexec -n 2 dlo-course train --preset recipe --nodes 6 --env-kwargs '{"threshold": 0.05}' \
        --stop-at-goal --validate-every 0 --episodes 130 --noise-sigma 0.3 --seed S \
        --out runs/recipe_n6_sigma03_sS
    dlo-course ship runs/recipe_n6_sigma03_sS data/checkpoints/seeds/nodes6_sigma0.3_seedS
    mpiexec -n 2 python benchmarks/seeds_table1.py run --nodes 6 --variant sigma0.3 \
        --what "OU noise sigma 0.3 (the paper's) instead of 0.15" \
        --agent 0=data/checkpoints/seeds/nodes6_sigma0.3_seed0 --agent S=...

In the scene of issue 35 (no dampers, the authors' clipped sweep), the lever is settled again
over seeds at the same budget (130 episodes per agent) before any long run: seeds 0, 1, 2 of
sigma 0.3 and of 0.15, with the command above and ``--out runs/i36_n6_sigma{0.3,0.15}_sS``;
``runs/`` is not in git, so each finished run is shipped to
``data/checkpoints/seeds/i36_n6_sigma{0.3,0.15}_seedS`` with its record, and a run that did not
finish has its resume state committed under ``data/checkpoints/resume/`` (copy it back to
``runs/`` and add ``--resume``). Their evaluations are the variants ``scene35-sigma0.3`` and
``scene35-sigma0.15``:

    mpiexec -n 2 python benchmarks/seeds_table1.py run --nodes 6 --variant scene35-sigma0.15 \
        --what "..." --agent 0=data/checkpoints/seeds/i36_n6_sigma0.15_seed0 --agent 1=...

The next lever for the 6-node large box is the budget: the three sigma 0.3 seeds were still
improving at their 130th episode (training success over the last 26 episodes 75, 83 and 81%
against 67-71% over the 26 before), so each is trained on to 260 episodes from its 130-episode
resume state (``episodes`` may be raised on resume, and nothing in a run depends on its total),
in a copy of its run folder, ``runs/i36_n6_sigma0.3_e260_sS`` (the 130-episode states, about
30 MB each, are not in git: where they are missing, leave out ``--resume``, and the run trains
its 260 episodes from the start with the same seed):

    mpiexec -n 2 dlo-course train --preset recipe --nodes 6 --env-kwargs '{"threshold": 0.05}' \
        --stop-at-goal --validate-every 0 --episodes 260 --noise-sigma 0.3 --seed S \
        --out runs/i36_n6_sigma0.3_e260_sS --resume
    dlo-course ship runs/i36_n6_sigma0.3_e260_sS data/checkpoints/seeds/i36_n6_sigma0.3_e260_seedS
    mpiexec -n 2 python benchmarks/seeds_table1.py run --nodes 6 --variant scene35-sigma0.3-e260 \
        --what "..." --agent 0=data/checkpoints/seeds/i36_n6_sigma0.3_e260_seed0 --agent 1=...

The 4- and 2-node seeds in that scene take the configurations of the agents shipped before
issue 36 (data/checkpoints/seeds/nodes{4,2}_seed0/record.json: sigma 0.15, 60-action
episodes that do not end at the goal, the best validated actor shipped), changing only the
seed:

    mpiexec -n 2 dlo-course train --preset recipe --nodes 4 --episodes 260 --seed S \
        --out runs/i36_n4_sS
    dlo-course ship runs/i36_n4_sS data/checkpoints/seeds/i36_n4_seedS --actor best
    mpiexec -n 2 dlo-course train --preset recipe --nodes 2 --episodes 500 --seed S \
        --out runs/i36_n2_sS
    dlo-course ship runs/i36_n2_sS data/checkpoints/seeds/i36_n2_seedS --actor best

and are evaluated on all eight cells of their node count, then validated to pick the one to
ship (the variant ``scene35``, as for 4 nodes here):

    mpiexec -n 2 python benchmarks/seeds_table1.py run --nodes 4 --variant scene35 --without \
        --what "..." --agent 0=data/checkpoints/seeds/i36_n4_seed0 --agent 1=... --agent 2=...
    mpiexec -n 2 python benchmarks/seeds_table1.py validate --nodes 4 --variant scene35 \
        --agent seed0=data/checkpoints/seeds/i36_n4_seed0 --agent seed1=... --agent seed2=...

Issue 49 trains the 4-node configuration at the 2-node budget (500 episodes per agent; seed 0
is ``data/checkpoints/seeds/i49_n4_seed0``, the variant ``scene35-e500``) and tries a lever
for its cells *with* reinitialisation, the ones below the paper: the recipe keeps the rod's
shape between training episodes, so an agent rarely starts from the straight rod that every
test episode with reinitialisation starts from (seed 0 at 500 episodes: 92/67% of the small
and 79/46% of the large test goals with reinitialisation, 97/71% and 87/58% without).
``--reset-between-episodes`` (the paper's text) rebuilds the world before every training
episode; at the budget of the ``scene35`` seeds (260 episodes, equal transitions):

    mpiexec -n 2 dlo-course train --preset recipe --nodes 4 --episodes 260 --seed S \
        --reset-between-episodes --out runs/i52_n4_reset_sS
    dlo-course ship runs/i52_n4_reset_sS data/checkpoints/seeds/i49_n4_reset_seedS --actor best
    mpiexec -n 2 python benchmarks/seeds_table1.py run --nodes 4 --variant scene35-reset \
        --what "..." --agent S=data/checkpoints/seeds/i49_n4_reset_seedS

Its seed 1, the like-test validation's pick (``benchmarks/validation_vs_test.py``), moved to
``data/checkpoints/nodes4``; pass that folder for it (``--agent 1=data/checkpoints/nodes4``).

Each agent's evaluation is cached in ``benchmarks/results/seeds/cache`` under its actor's
digest (the cache of ``dlo-course reproduce``), so a stopped run resumes at the agent it was in
and a report can be rebuilt on any machine. ``report`` writes
``benchmarks/results/seeds/nodesN.md`` and ``.csv`` from the cached evaluations.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
from pathlib import Path

from dlo_course import mpi
import numpy as np

from dlo_course.database import load_database
from dlo_course.docs_numbers import (SEEDS_INTERVAL, format_done_interval,
                                     format_row_interval)
from dlo_course.evaluation import (Summary, evaluate_thresholds, seed_interval,
                                   wilson_interval)
from dlo_course.reproduce import (Cell, actor_digest, evaluate_cells, read_paper_table,
                                  table1_cells)
from dlo_course.rundir import agent_dir, run_record
from dlo_course.task import TABLE_THRESHOLDS

RESULTS = Path(__file__).parent / "results" / "seeds"
CACHE = RESULTS / "cache"
EPISODES, MAX_STEPS, GOAL_SEED = 100, 30, 0  # the protocol of docs/reproduction/table1.csv
VALIDATION_SEED = 7  # another draw than the test's, on other goals


def cells(nodes: int, without: bool = False) -> list[Cell]:
    """The node count's Table I cells with reinitialisation, and without if ``without``."""
    return [Cell(r, nodes, db, t) for r in ("with", "without")[:1 + without]
            for db in ("small", "large") for t in TABLE_THRESHOLDS]


def _stem(nodes: int, variant: str | None) -> str:
    """The results' file names: ``nodesN`` for the shipped configuration, ``nodesN_VARIANT``
    for another one (a lever changed)."""
    return f"nodes{nodes}" + (f"_{variant}" if variant else "")


def _layout(seed: int, folder: Path, nodes: int, variant: str | None = None) -> Path:
    # evaluate_cells reads agents from ROOT/nodesN: give each seed's agent such a root.
    root = Path("reports") / "seeds_layout" / (variant or "shipped") / f"seed{seed}"  # symlinks
    link = agent_dir(root, nodes)
    if mpi.is_root():
        link.parent.mkdir(parents=True, exist_ok=True)
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(Path(folder).resolve(), target_is_directory=True)
    mpi.barrier()
    return root


def run(nodes: int, agents: dict[int, Path], variant: str | None = None,
        what: str | None = None, without: bool = False) -> None:
    manifest = {}
    for seed, folder in sorted(agents.items()):
        if not (Path(folder) / "actor.pt").is_file():
            raise FileNotFoundError(f"seed {seed}: no actor.pt in {folder}")
        rows = evaluate_cells(_layout(seed, folder, nodes, variant), EPISODES, MAX_STEPS,
                              GOAL_SEED,
                              cells=cells(nodes, without), protocol="test", cache=CACHE)
        if mpi.is_root():
            record = run_record(folder)
            manifest[str(seed)] = {"agent": str(folder), "transitions": record.get("transitions"),
                                   "episodes_per_agent": record.get("episodes_per_agent"),
                                   "wall_time_h": record.get("wall_time_h"),
                                   "rows": [{**r, "cell": r["cell"].key} for r in rows]}
    if mpi.is_root():
        RESULTS.mkdir(parents=True, exist_ok=True)
        if what:
            manifest["what"] = what
        (RESULTS / f"{_stem(nodes, variant)}_runs.json").write_text(
            json.dumps(manifest, indent=1) + "\n")
        report(nodes, variant)


def report(nodes: int, variant: str | None = None) -> str:
    manifest = json.loads((RESULTS / f"{_stem(nodes, variant)}_runs.json").read_text())
    what = manifest.pop("what", None)
    paper = read_paper_table()
    seeds = sorted(manifest, key=int)
    # the cells every seed was evaluated on (a run with --without adds the chained ones)
    evaluated = set.intersection(*({tuple(r["cell"]) for r in manifest[s]["rows"]}
                                   for s in seeds))
    table_cells = [c for c in cells(nodes, without=True) if c.key in evaluated]
    reinits = sorted({c.reinit for c in table_cells}, reverse=True)  # "with" first
    lines = [f"# Table I over training seeds: {nodes} nodes, "
             + " and ".join(f"{r} reinitialisation" for r in reinits)
             + (f", variant `{variant}`" if variant else ""),
             "",
             *([f"What the variant changes from the shipped configuration: {what}.", ""]
               if what else []),
             f"{EPISODES} test episodes per cell and seed (goal draw seed {GOAL_SEED}, at most "
             f"{MAX_STEPS} actions), made by `mpiexec -n 2 python benchmarks/seeds_table1.py run "
             f"--nodes {nodes}{f' --variant {variant}' if variant else ''} ...` (the module "
             f"docstring). Per seed: done % [95% Wilson interval "
             f"over the episodes]. Over seeds: mean [95% t-interval over the {len(seeds)} seeds"
             f"{'' if len(seeds) > 1 else ': none with one seed'}]; "
             f"pooled: all seeds' episodes [95% Wilson interval; the seeds play the same goals]. "
             f"The verdict (ours above, within or below the paper) compares the paper's number "
             f"with the union of the two intervals.",
             "",
             "| reinit | database | threshold | " + " | ".join(f"seed {s}" for s in seeds)
             + " | mean over seeds | pooled episodes | paper | ours vs paper |",
             "|---|---|---|" + "---|" * len(seeds) + "---|---|---|---|"]
    table = []
    for cell in table_cells:
        per_seed = []
        for s in seeds:
            row = next(r for r in manifest[s]["rows"] if tuple(r["cell"]) == cell.key)
            per_seed.append(row)
        done = [r["done_percent"] for r in per_seed]
        # One seed (a variant's first): no spread between seeds to measure, the episodes' only.
        mean, low, high = seed_interval(done) if len(done) > 1 else (done[0],) * 3
        episodes = sum(r["episodes"] for r in per_seed)
        successes = round(sum(r["done_percent"] * r["episodes"] / 100 for r in per_seed))
        pooled_low, pooled_high = (100 * x for x in wilson_interval(successes, episodes))
        paper_done = paper[cell.key]["done_percent"]
        union_low, union_high = min(low, pooled_low), max(high, pooled_high)
        # The course's verdict (reproduce.verdict): where ours lies against the paper's number.
        where = ("below" if paper_done > union_high else "above" if paper_done < union_low
                 else "within")
        lines.append(f"| {cell.reinit} | {cell.database} | {cell.threshold:g} | "
                     + " | ".join(f"{r['done_percent']:.0f} [{r['done_ci_low']:.0f}, "
                                  f"{r['done_ci_high']:.0f}]" for r in per_seed)
                     + (f" | {format_done_interval(mean, low, high)} | "
                        if len(done) > 1 else f" | {mean:.1f} [one seed] | ")
                     + f"{100 * successes / episodes:.1f} [{pooled_low:.1f}, {pooled_high:.1f}] | "
                     f"{paper_done:g} | {where} |")
        table.append({"reinit": cell.reinit, "nodes": nodes, "database": cell.database, "threshold": cell.threshold,
                      **{f"seed{s}_done_percent": r["done_percent"] for s, r in zip(seeds, per_seed)},
                      "mean_done_percent": mean, "seed_ci_low": low, "seed_ci_high": high,
                      "pooled_episodes": episodes, "pooled_ci_low": pooled_low,
                      "pooled_ci_high": pooled_high, "paper_done_percent": paper_done,
                      "verdict": where})
    lines += ["", "The agents:", ""]
    for s in seeds:
        m = manifest[s]
        hours = m.get("wall_time_h")
        lines.append(f"- seed {s}: `{m['agent']}`, {m.get('transitions')} transitions, "
                     f"{m.get('episodes_per_agent')} episodes per agent"
                     + (f", {hours:.2f} h of training" if hours else ""))
    text = "\n".join(lines) + "\n"
    (RESULTS / f"{_stem(nodes, variant)}.md").write_text(text)
    with open(RESULTS / f"{_stem(nodes, variant)}.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table)
    print(text)
    return text


def table(variants: dict[int, str | None]) -> str:
    """Table I over seeds for every node count given: the rows of each ``nodesN[_VARIANT].csv``
    (written by ``report``) in the paper's order, and how many cells the paper's number lies
    above ours (``below``), within or under our intervals. Writes ``table1_seeds.md`` for
    people and ``table1_seeds.csv`` (one row per cell) for the README's generated line."""
    rows = []
    for nodes, variant in sorted(variants.items()):
        path = RESULTS / f"{_stem(nodes, variant)}.csv"
        if not path.is_file():
            raise FileNotFoundError(f"{path} is missing: run `seeds_table1.py run --nodes {nodes}"
                                    f"{f' --variant {variant}' if variant else ''} ...` first")
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                seeds = [k for k in row if k.startswith("seed") and k.endswith("_done_percent")]
                rows.append({**row, "reinit": row.get("reinit", "with"), "variant": variant,
                             "seeds": len(seeds)})
    order = {key: i for i, key in enumerate(c.key for c in table1_cells())}
    rows.sort(key=lambda r: order[(r["reinit"], int(r["nodes"]), r["database"],
                                   round(float(r["threshold"]), 4))])
    counts = {v: sum(r["verdict"] == v for r in rows) for v in ("above", "within", "below")}
    lines = ["# Table I over training seeds", "",
             "Each node count's cells from its report (`seeds_table1.py report`), made by "
             "`python benchmarks/seeds_table1.py table "
             + " ".join(f"--use {n}={v}" if v else f"--use {n}" for n, v in
                        sorted(variants.items())) + "`. Mean done % over the seeds [95% "
             "t-interval]; the verdict compares the paper's number with the union of that "
             "interval and the pooled episodes' Wilson interval.", "",
             f"**{len(rows)} cells: the paper's done % is not significantly above ours in "
             f"{counts['above'] + counts['within']}** (ours above in {counts['above']}, within "
             f"in {counts['within']}, below in {counts['below']}).", "",
             "| reinit | nodes | database | threshold | agents | seeds | mean over seeds | "
             "paper | ours vs paper |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['reinit']} | {r['nodes']} | {r['database']} | "
                     f"{float(r['threshold']):g} | {r['variant'] or 'shipped configuration'} | "
                     f"{r['seeds']} | {format_row_interval(r)} | "
                     f"{float(r['paper_done_percent']):g} | {r['verdict']} |")
    text = "\n".join(lines) + "\n"
    (RESULTS / "table1_seeds.md").write_text(text)
    fields = ["reinit", "nodes", "database", "threshold", "variant", "seeds", *SEEDS_INTERVAL,
              "paper_done_percent", "verdict"]
    with open(RESULTS / "table1_seeds.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    print(text)
    return text


def held_out_goals(nodes: int) -> np.ndarray:
    """(K, nodes, 3): the small database's records that are not the paper's test goals (the
    trainer's validation goals come from the same set, dlo_course.trainer.validation_indices)."""
    database = load_database("small")
    goals = database.goals(nodes)
    return goals[np.setdiff1d(np.arange(len(goals)), database.test_indices(nodes))]


def _validation_scores(nodes: int, folder: Path, goals: np.ndarray) -> dict[float, Summary]:
    """One agent's validation, cached under its actor's digest like the test runs: a stopped
    validation resumes at the agent it was in, and an agent is validated once whatever its
    label or the other candidates."""
    digest = actor_digest(folder)
    saved = CACHE / (f"validation_n{nodes}_e{EPISODES}_s{MAX_STEPS}_seed{VALIDATION_SEED}_"
                     f"{digest}.json")
    if saved.is_file():  # every rank sees the same file
        return {float(t): Summary(**row) for t, row in json.loads(saved.read_text()).items()}
    results = evaluate_thresholds(folder, goals, TABLE_THRESHOLDS, reinitialize=True,
                                  episodes=EPISODES, max_steps=MAX_STEPS, seed=VALIDATION_SEED,
                                  n_nodes=nodes, show_progress=False)
    if mpi.is_root():
        scores = {t: results[t][0] for t in TABLE_THRESHOLDS}
        CACHE.mkdir(parents=True, exist_ok=True)
        saved.write_text(json.dumps({str(t): v.as_dict() for t, v in scores.items()},
                                    indent=1) + "\n")
    mpi.barrier()  # the other ranks read the file rank 0 wrote
    return {float(t): Summary(**row) for t, row in json.loads(saved.read_text()).items()}


def validate(nodes: int, agents: dict[str, Path], variant: str | None = None) -> str:
    """Which agent validation picks: Table I's protocol on held-out goals (module docstring).

    ``agents`` maps a label (a seed, or e.g. ``sigma0.3-seed1`` when the candidates differ by
    a lever as well) to the agent's folder."""
    goals = held_out_goals(nodes)
    scores = {label: _validation_scores(nodes, folder, goals)
              for label, folder in agents.items()}
    if not mpi.is_root():
        return ""
    strict, loose = min(TABLE_THRESHOLDS), max(TABLE_THRESHOLDS)
    pick = max(scores, key=lambda s: (scores[s][strict].done_percent,
                                      scores[s][loose].done_percent,
                                      -scores[s][strict].mean_distance))
    lines = [f"# Which agent validation picks: {nodes} nodes"
             + (f", variant `{variant}`" if variant else ""), "",
             f"Table I's protocol (with reinitialisation, {EPISODES} episodes, at most "
             f"{MAX_STEPS} actions, goal draw seed {VALIDATION_SEED}) on the {len(goals)} "
             f"records of the small database that are not the paper's test goals; made by "
             f"`mpiexec -n 2 python benchmarks/seeds_table1.py validate --nodes {nodes} ...`. "
             f"Ranked by done % at {strict:g} m, then at {loose:g} m, then by the mean final "
             f"distance at {strict:g} m. The test goals play no part.", "",
             f"| agent | folder | done % at {loose:g} m | done % at {strict:g} m | mean final "
             f"distance at {strict:g} m |", "|---|---|---|---|---|"]
    for label, by_threshold in scores.items():
        low, high = by_threshold[loose], by_threshold[strict]
        lines.append(f"| {label}{' (picked)' if label == pick else ''} | `{agents[label]}` | "
                     f"{low.done_percent:.0f} [{low.done_ci_low:.0f}, {low.done_ci_high:.0f}] | "
                     f"{high.done_percent:.0f} [{high.done_ci_low:.0f}, "
                     f"{high.done_ci_high:.0f}] | {high.mean_distance:.4f} |")
    text = "\n".join(lines) + "\n"
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{_stem(nodes, variant)}_validation.md").write_text(text)
    print(text)
    return text


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("run", "report", "validate", "table"))
    parser.add_argument("--nodes", type=int, choices=(2, 4, 6),
                        help="the node count (run, report, validate)")
    parser.add_argument("--use", action="append", default=[], metavar="NODES[=VARIANT]",
                        help="table: a node count and the variant whose report it takes "
                             "(repeatable)")
    parser.add_argument("--agent", action="append", default=[], metavar="SEED=FOLDER",
                        help="a trained agent (run directory or agent folder) and its seed")
    parser.add_argument("--variant", default=None, metavar="NAME",
                        help="agents trained with a lever changed: results in nodesN_NAME.*")
    parser.add_argument("--what", default=None,
                        help="with --variant: what it changes, in words, for the report")
    parser.add_argument("--without", action="store_true",
                        help="run: the cells without reinitialisation too (chained episodes, "
                             "about three times the minutes of the cells with)")
    args = parser.parse_args(argv)
    if args.variant is not None and not args.variant.replace("-", "").replace(".", "").isalnum():
        parser.error(f"--variant wants a plain name, got {args.variant!r}")
    if args.command == "table":
        if not args.use:
            parser.error("table wants at least one --use NODES[=VARIANT]")
        variants = {}
        for item in args.use:
            nodes, _, variant = item.partition("=")
            if nodes not in ("2", "4", "6"):
                parser.error(f"--use wants NODES[=VARIANT] with NODES 2, 4 or 6, got {item!r}")
            variants[int(nodes)] = variant or None
        try:
            table(variants)
        except FileNotFoundError as missing:
            parser.error(str(missing))
        return
    if args.nodes is None:
        parser.error(f"{args.command} wants --nodes")
    if args.command == "report":
        report(args.nodes, args.variant)
        return
    agents = {}
    for item in args.agent:
        label, _, folder = item.partition("=")
        # run: the label is the training seed; validate: any plain name (the candidates may
        # differ by a lever as well as by the seed)
        plain = label.replace("-", "").replace(".", "").replace("_", "").isalnum()
        if not folder or not (label.isdigit() if args.command == "run" else plain):
            parser.error(f"--agent wants {'SEED' if args.command == 'run' else 'LABEL'}=FOLDER, "
                         f"got {item!r}")
        if not (Path(folder) / "actor.pt").is_file():
            parser.error(f"--agent {label}: no actor.pt in {folder}")
        agents[label] = Path(folder)
    if args.command == "validate":
        if len(agents) < 2:
            parser.error("give at least two --agent LABEL=FOLDER to choose among")
        validate(args.nodes, agents, args.variant)
        return
    if len(agents) < (1 if args.variant else 2):
        parser.error("give at least two --agent SEED=FOLDER: an interval over seeds needs two "
                     "(a --variant may start with one)")
    run(args.nodes, {int(k): v for k, v in agents.items()}, args.variant, args.what,
        args.without)


if __name__ == "__main__":
    os.environ.setdefault("MPLBACKEND", "Agg")
    main(sys.argv[1:])
