"""``dlo-course reproduce``: the paper's Table I and figures, regenerated beside the paper's.

By default it evaluates the shipped agents (``data/checkpoints/nodes{2,4,6}``) on all 24
settings of Table I with a reduced number of episodes per setting, and writes into ``--out``:

* ``table1.csv`` and ``table1.md``: our numbers, the paper's (``data/paper/table1.csv``) and
  the differences, with the 95% interval of our done %;
* ``fig4_learning_curves.png``: the training curves of the agents (the paper's Fig. 4);
* ``fig5_deformation.png``: the robot deforming the rod to a goal from the large database
  that lies outside the training box (the paper's Fig. 5);
* ``report.md``: which settings produced the numbers (time per action, gradient reduction,
  training budget, episodes per cell).

Runs on every MPI rank: under ``mpiexec -n N`` the episodes of each setting are split over the
ranks (see :mod:`dlo_course.evaluation`).
"""

from __future__ import annotations

import csv
import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

from tqdm.auto import tqdm

from dlo_course import mpi
from dlo_course.config import DDPGConfig, TrainConfig, preset
from dlo_course.database import BOXES, load_database
from dlo_course.evaluation import evaluate_thresholds, load_actor, wilson_interval
from dlo_course.paths import AGENTS_DIR, DATA_DIR, REPO_ROOT
from dlo_course.plots import plot_deformation, plot_learning_curves
from dlo_course.rundir import agent_dir, training_record, write_json
from dlo_course.task import NODE_COUNTS, TABLE_THRESHOLDS
from dlo_course.trainer import train

PAPER_TABLE = DATA_DIR / "paper" / "table1.csv"


@dataclass(frozen=True)
class Cell:
    """One setting (row) of Table I."""

    reinit: str  # "with" or "without"
    nodes: int
    database: str  # "small" or "large"
    threshold: float

    @property
    def key(self) -> tuple:
        return (self.reinit, self.nodes, self.database, round(self.threshold, 4))


def table1_cells(nodes: tuple[int, ...] = NODE_COUNTS) -> list[Cell]:
    """The 24 settings in the paper's order (8 per node count: those of ``nodes`` only)."""
    return [Cell(r, n, db, thr) for r in ("with", "without") for n in NODE_COUNTS if n in nodes
            for db in ("small", "large") for thr in TABLE_THRESHOLDS]


def read_paper_table(path: Path = PAPER_TABLE) -> dict[tuple, dict[str, float]]:
    """The paper's Table I, keyed like :attr:`Cell.key`."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"the paper's Table I is missing: {path}")
    table = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            cell = Cell(row["reinit"], int(row["nodes"]), row["database"], float(row["threshold"]))
            table[cell.key] = {k: float(row[k]) for k in
                               ("done_percent", "mean_distance", "std_distance", "best_distance")}
    return table


def train_agents(preset_name: str, out: Path, seed: int = 0,
                 nodes: tuple[int, ...] = NODE_COUNTS) -> Path:
    """Train one agent per node count of ``nodes`` with a trainer preset; returns the folder
    of their run directories (``out/checkpoints/nodes{2,4,6}``), which are trained agents."""
    root = Path(out) / "checkpoints"
    for n in nodes:
        config = preset(preset_name, env_kwargs={"n_nodes": n}, seed=seed,
                        out_dir=str(agent_dir(root, n)))
        train(config, resume=True, progress=mpi.is_root())
    return root


GOAL_PROTOCOLS = {
    "test": "the paper's test goals (`small-test`, `large-test`): the goals Table I was "
            "measured on, mostly the sweep's first, uncompressed level",
    "whole": "goals drawn uniformly from the whole database (`small`, `large`): a harder "
             "protocol the paper did not run",
}


def goal_source(database: str, protocol: str) -> str:
    """The goal source of a Table I cell: ``"small-test"`` for the paper's protocol."""
    if protocol not in GOAL_PROTOCOLS:
        raise ValueError(f"goal protocol must be one of {sorted(GOAL_PROTOCOLS)}, got {protocol!r}")
    return f"{database}-test" if protocol == "test" else database


def actor_digest(agent: Path) -> str:
    """The name of an agent's cached evaluations: the first 12 hex digits of its actor's
    SHA-256 (an off-the-shelf agent's: its model file's, :mod:`dlo_course.baselines`)."""
    from dlo_course.baselines import SB3_MODEL_FILE

    policy = Path(agent) / "actor.pt"
    if not policy.is_file() and (Path(agent) / SB3_MODEL_FILE).is_file():
        policy = Path(agent) / SB3_MODEL_FILE
    return hashlib.sha256(policy.read_bytes()).hexdigest()[:12]


def _policy(agents: Path | None, controller: str | None, n_nodes: int) -> tuple[object, str]:
    """What plays a cell's episodes, and a digest that names it for the cache: the trained
    agent of ``agents`` (its actor's weights) or the named classical controller (its
    settings)."""
    if controller is None:
        agent = agent_dir(agents, n_nodes)
        return agent, actor_digest(agent)
    from dlo_course.jacobian import CONTROLLERS  # only when a controller is asked for

    policy = CONTROLLERS[controller](n_nodes)
    settings = json.dumps({k: v for k, v in sorted(vars(policy).items())
                           if isinstance(v, (int, float, str))})
    return policy, hashlib.sha256(settings.encode()).hexdigest()[:12]


def evaluate_cells(agents: Path | None, episodes: int, max_steps: int, seed: int,
                   time_mode: str = "code", cells: list[Cell] | None = None,
                   protocol: str = "test", cache: Path | None = None,
                   controller: str | None = None) -> list[dict]:
    """Evaluate every cell; on rank 0 returns one dict per cell, elsewhere an empty list.

    Cells that differ only by threshold share their episodes when the world is reinitialised
    (:func:`dlo_course.evaluation.evaluate_thresholds`): 12 runs make the 24 cells.

    Args:
        agents: the folder of trained agents (``nodes{2,4,6}``); ignored with ``controller``.
        cache: a folder where each finished run leaves its results (with the minutes it
            took), reused when the same agent is evaluated the same way again: a stopped
            reproduction resumes at the run it was in instead of starting over.
        controller: evaluate this classical controller (a name of
            :data:`dlo_course.jacobian.CONTROLLERS`, default settings) instead of the agents.
    """
    cells = cells or table1_cells()
    groups: dict[tuple, list[Cell]] = {}
    for cell in cells:
        key = (cell.reinit, cell.nodes, cell.database) + (
            () if cell.reinit == "with" else (cell.threshold,))
        groups.setdefault(key, []).append(cell)
    prefix = protocol if controller is None else f"{controller}_{protocol}"
    results: dict[Cell, dict] = {}
    for group in tqdm(groups.values(), desc=f"Table I ({prefix} goals)", unit="run",
                      disable=not mpi.is_root()):
        first = group[0]
        policy, identity = _policy(agents, controller, first.nodes)
        thresholds = "-".join(f"{c.threshold:g}" for c in group)
        saved = None if cache is None else cache / (
            f"{prefix}_{first.reinit}_n{first.nodes}_{first.database}_t{thresholds}_"
            f"e{episodes}_s{max_steps}_seed{seed}_{time_mode}_{identity}.json")
        if saved is not None and saved.is_file():  # every rank sees the same files
            done = json.loads(saved.read_text())
        else:
            began = time.perf_counter()
            by_threshold = evaluate_thresholds(
                policy, goal_source(first.database, protocol),
                [cell.threshold for cell in group], reinitialize=first.reinit == "with",
                episodes=episodes, max_steps=max_steps, seed=seed, n_nodes=first.nodes,
                time_mode=time_mode, show_progress=False)
            # the rank count travels with the minutes: a report re-rendered from this cache
            # under another mpiexec must not credit these minutes to its own ranks
            done = {"minutes": (time.perf_counter() - began) / 60, "ranks": mpi.size(),
                    "summaries": {
                f"{t:g}": (s.as_dict() if s is not None else None)
                for t, (s, _) in by_threshold.items()}}
            if saved is not None and mpi.is_root():
                saved.parent.mkdir(parents=True, exist_ok=True)
                write_json(done, saved)
            mpi.barrier()
        for cell in group:
            summary = done["summaries"][f"{cell.threshold:g}"]
            if summary is not None and mpi.is_root():
                results[cell] = {"cell": cell, **summary, "minutes": done["minutes"],
                                 "ranks": done.get("ranks"), "run_cells": len(group)}
    return [results[cell] for cell in cells if cell in results]


def evaluate_controller_cells(controller: str, episodes: int, max_steps: int, seed: int,
                              time_mode: str = "code", cells: list[Cell] | None = None,
                              protocol: str = "test", cache: Path | None = None
                              ) -> list[dict]:
    """:func:`evaluate_cells` for a classical controller instead of the trained agents: the
    same cells, goals, episodes and protocol, rows in the same format; a run is cached under
    the controller's name and settings instead of an actor's digest."""
    from dlo_course.jacobian import CONTROLLERS

    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {sorted(CONTROLLERS)}, got {controller!r}")
    return evaluate_cells(None, episodes, max_steps, seed, time_mode, cells, protocol, cache,
                          controller=controller)


def evaluation_minutes(rows: list[dict], reinit: str | None = None) -> float:
    """Minutes the runs behind ``rows`` took (those ``reinit``: "with" or "without", or
    all), counting a run shared by two cells once, whichever invocation ran it."""
    return sum(r["minutes"] / r["run_cells"] for r in rows
               if reinit is None or r["cell"].reinit == reinit)


def _ranks_phrase(rows: list[dict]) -> str:
    """On how many ranks the runs behind ``rows`` were made, from their records; runs cached
    before the count was recorded say so instead of borrowing this invocation's count."""
    counts = {r.get("ranks") for r in rows}
    known = sorted(c for c in counts if c is not None)
    if not known:
        return "on a rank count not recorded"
    return (f"on {' or '.join(map(str, known))} rank(s)"
            + (" (runs cached earlier: rank count not recorded)" if None in counts else ""))


def _time_note(rows: list[dict]) -> str:
    with_, without = evaluation_minutes(rows, "with"), evaluation_minutes(rows, "without")
    return (f"{with_ + without:.0f} min of evaluation {_ranks_phrase(rows)}: "
            f"{with_:.0f} with reinitialisation, {without:.0f} without")


def verdict(row: dict, paper_done: float) -> str:
    """Where the paper's done % lies against our 95% interval: "above" (ours is significantly
    above the paper's), "within", or "below"."""
    if paper_done < row["done_ci_low"]:
        return "above"
    if paper_done > row["done_ci_high"]:
        return "below"
    return "within"


def done_verdict(successes: int, episodes: int, paper_done: float) -> str:
    """:func:`verdict` of a done % measured as ``successes`` of ``episodes``: its 95% Wilson
    interval (:func:`dlo_course.evaluation.wilson_interval`), in percent, against the paper's
    done % (``paper_done``, in percent). Lesson 10's ``table_verdict``; lessons 11 and 13 use
    it."""
    low, high = (100 * x for x in wilson_interval(successes, episodes))
    return verdict({"done_ci_low": low, "done_ci_high": high}, paper_done)


def write_table(rows: list[dict], paper: dict, out: Path, name: str = "table1"
                ) -> tuple[Path, Path]:
    """``NAME.csv`` and ``NAME.md``: ours, the paper's and the difference per setting, with
    a verdict (:func:`verdict`)."""
    out.mkdir(parents=True, exist_ok=True)
    fields = ["reinit", "nodes", "database", "threshold", "episodes",
              "done_percent", "done_ci_low", "done_ci_high", "paper_done_percent", "done_diff",
              "verdict", "mean_distance", "std_distance", "paper_mean_distance",
              "paper_std_distance", "mean_diff", "best_distance", "paper_best_distance",
              "best_diff"]
    csv_path, md_path = out / f"{name}.csv", out / f"{name}.md"
    lines = [
        "| reinit | nodes | db | thr | episodes | done % (95% CI) | paper done % | Δ done | "
        "ours vs paper | mean ± σ (m) | paper mean ± σ (m) | best (m) | paper best (m) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    with open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            cell = row["cell"]
            ref = paper[cell.key]
            record = {
                "reinit": cell.reinit, "nodes": cell.nodes, "database": cell.database,
                "threshold": cell.threshold, "episodes": row["episodes"],
                "done_percent": row["done_percent"], "done_ci_low": row["done_ci_low"],
                "done_ci_high": row["done_ci_high"],
                "paper_done_percent": ref["done_percent"],
                "done_diff": row["done_percent"] - ref["done_percent"],
                "verdict": verdict(row, ref["done_percent"]),
                "mean_distance": row["mean_distance"], "std_distance": row["std_distance"],
                "paper_mean_distance": ref["mean_distance"],
                "paper_std_distance": ref["std_distance"],
                "mean_diff": row["mean_distance"] - ref["mean_distance"],
                "best_distance": row["best_distance"],
                "paper_best_distance": ref["best_distance"],
                "best_diff": row["best_distance"] - ref["best_distance"],
            }
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v)
                             for k, v in record.items()})
            lines.append(
                f"| {cell.reinit} | {cell.nodes} | {cell.database} | {cell.threshold} | "
                f"{row['episodes']} | {row['done_percent']:.1f} ({row['done_ci_low']:.1f}–"
                f"{row['done_ci_high']:.1f}) | {ref['done_percent']:.1f} | "
                f"{record['done_diff']:+.1f} | {record['verdict']} | "
                f"{row['mean_distance']:.5f} ± "
                f"{row['std_distance']:.5f} | {ref['mean_distance']:.5f} ± "
                f"{ref['std_distance']:.5f} | {row['best_distance']:.5f} | "
                f"{ref['best_distance']:.5f} |")
    md_path.write_text("\n".join(lines) + "\n")
    return csv_path, md_path


def database_protocols() -> str:
    """How each database was recorded, for the report (e.g. "small: authors_sweep, ...")."""
    return ", ".join(f"{name}: {load_database(name).protocol} protocol" for name in BOXES)


def course_options(record: dict) -> str:
    """The course options a training used, in words ("none" for the paper's DDPG)."""
    paper, paper_updates = DDPGConfig(), TrainConfig().updates_per_step
    parts = []
    if record.get("normalize_obs"):
        parts.append("input scaling")
    if record.get("preactivation_l2"):
        parts.append(f"pre-tanh penalty {record['preactivation_l2']:g}")
    if record.get("updates_per_step", paper_updates) != paper_updates:
        parts.append(f"{record['updates_per_step']} updates/step")
    if record.get("noise_sigma") not in (None, paper.noise_sigma):
        parts.append(f"OU sigma {record['noise_sigma']:g}")
    if record.get("her_k"):
        parts.append(f"HER k={record['her_k']}")
    if record.get("reset_between_episodes") is False:
        parts.append("no reset between episodes")
    if record.get("batch_size") not in (None, paper.batch_size):
        parts.append(f"batch {record['batch_size']}")
    if record.get("buffer_size") not in (None, paper.buffer_size):
        parts.append(f"buffer {record['buffer_size']}")
    if record.get("twin_critics"):
        parts.append("twin critics")
    if record.get("policy_delay", paper.policy_delay) != paper.policy_delay:
        parts.append(f"policy delay {record['policy_delay']}")
    if record.get("target_noise"):
        parts.append(f"target noise {record['target_noise']:g}")
    if record.get("stop_at_goal"):
        parts.append("episodes end at the goal")
    if record.get("train_threshold") is not None:
        parts.append(f"trained at {record['train_threshold']:g} m")
    return ", ".join(parts) or "none"


DEFAULT_EPISODES = 50
"""Test episodes per setting by default: with them the default run (Table I's 24 settings)
took 18.4 minutes on 2 cores in a fresh clone (install not counted), under the 45 minutes a
first look may take (benchmarks/results/reproduction_time_default.txt); 100 (the committed
report) takes about an hour, of which 46 minutes are the runs without
reinitialisation (benchmarks/results/reproduction_time.txt)."""
WHOLE_DATABASE_CELLS = {"with": "with", "all": None, "none": ()}
"""Which cells the whole-database table covers: those "with" reinitialisation, all, or none."""
PAPER_CORE_HOURS = 32 * 3.5  # 32 cores for under 3.5 h
PAPER_TRANSITIONS = 32 * 63 * 300
SEEDS_TABLE = REPO_ROOT / "benchmarks" / "results" / "seeds" / "table1_seeds.md"
"""Table I over three training seeds of each shipped configuration, made by
``benchmarks/seeds_table1.py table`` (hours of training and evaluation: not re-run here)."""


def seeds_section(checkpoints: Path, nodes: tuple[int, ...], table: Path = SEEDS_TABLE
                  ) -> list[str]:
    """The report's lines on the seeds table: one shipped agent per node count is one draw of
    its training, and the seeds say whether its verdicts hold for the configuration. Only for
    the shipped agents of all three node counts (the seeds are of their configurations), and
    only if the committed table is there; otherwise no lines."""
    if Path(checkpoints).resolve() != AGENTS_DIR.resolve() or nodes != NODE_COUNTS \
            or not table.is_file():
        return []
    body = table.read_text().split("\n", 1)[1].strip()  # without its own title
    return ["", "## The same cells over training seeds (committed, not re-run by this command)",
            "", f"From `{table.relative_to(REPO_ROOT)}`: three seeds of each shipped agent's "
            "training configuration, 100 episodes per cell and seed on the same goals. Read the "
            "shipped agents' verdicts above against these: where they differ, the seeds' say "
            "what the configuration does, the shipped agent's what one training run did.",
            "", body]


def reproduce(out: Path, checkpoints: Path | None = None, episodes: int = DEFAULT_EPISODES,
              max_steps: int = 30, seed: int = 0, train_preset: str | None = None,
              time_mode: str = "code", whole_database: str = "none",
              controller: str | None = None, controller_cells: str = "with",
              nodes: tuple[int, ...] = NODE_COUNTS) -> Path | None:
    """Regenerate Table I and Figs. 4-5 (see the module docstring); returns the report path
    on rank 0.

    Args:
        checkpoints: the folder of trained agents, ``nodes{2,4,6}`` (:func:`agent_dir`);
            default the shipped ones.
        whole_database: which cells also get the harder protocol, goals drawn from the whole
            database: "with" (the 12 cells with reinitialisation), "all" or "none".
        controller: also evaluate this classical controller ("jacobian",
            :func:`evaluate_controller_cells`) on the paper's test goals, every cell, and
            write its table beside the agents' (``table1_<controller>.csv``, ``.md``) and in
            the report. None (default): the agents only.
        controller_cells: which cells the controller plays: "with" reinitialisation (the
            default: with the forked resets, a few minutes per run), or "all".
        nodes: the node counts whose rows are made (default all three: the whole table);
            only their agents are needed. Fig. 5 shows the 4-node agent, or the first of
            ``nodes`` without it.

    Every finished evaluation run leaves its results in ``out/runs/``; running the same
    command again reuses them (for the same agents, episodes and seed), so a reproduction
    stopped halfway resumes where it was.
    """
    if whole_database not in WHOLE_DATABASE_CELLS:
        raise ValueError(f"whole_database must be one of {sorted(WHOLE_DATABASE_CELLS)}")
    if controller_cells not in ("with", "all"):
        raise ValueError(f"controller_cells must be 'with' or 'all', got {controller_cells!r}")
    if controller is not None:  # a wrong name fails now, not after the agents' hour
        from dlo_course.jacobian import CONTROLLERS

        if controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {sorted(CONTROLLERS)}, "
                             f"got {controller!r}")
    nodes = tuple(sorted(set(int(n) for n in nodes)))
    if not nodes or any(n not in NODE_COUNTS for n in nodes):
        raise ValueError(f"nodes must be among {NODE_COUNTS}, got {nodes}")
    out = Path(out)
    paper = read_paper_table()
    if train_preset is not None:
        checkpoints = train_agents(train_preset, out, seed, nodes)
    checkpoints = Path(checkpoints or AGENTS_DIR)
    for n in nodes:  # a missing or wrong agent fails now, not after an hour of evaluation
        load_actor(agent_dir(checkpoints, n), n)
    cache = out / "runs"
    rows = evaluate_cells(checkpoints, episodes, max_steps, seed, time_mode, protocol="test",
                          cells=table1_cells(nodes), cache=cache)
    scope = WHOLE_DATABASE_CELLS[whole_database]
    whole_cells = [c for c in table1_cells(nodes) if scope is None or c.reinit == scope]
    whole_rows = (evaluate_cells(checkpoints, episodes, max_steps, seed, time_mode,
                                 cells=whole_cells, protocol="whole", cache=cache)
                  if whole_cells else [])
    scope = WHOLE_DATABASE_CELLS[controller_cells]
    controller_rows = (evaluate_controller_cells(
        controller, episodes, max_steps, seed, time_mode, protocol="test", cache=cache,
        cells=[c for c in table1_cells(nodes) if scope is None or c.reinit == scope])
        if controller is not None else [])
    if not mpi.is_root():
        return None
    csv_path, md_path = write_table(rows, paper, out)
    tables = [("## Table I: ours beside the paper's, on the paper's test goals", md_path,
               f"Goals: {GOAL_PROTOCOLS['test']}. {_time_note(rows)}.")]
    if whole_rows:
        _, whole_md = write_table(whole_rows, paper, out, name="table1_whole_database")
        tables.append(("## The harder protocol: goals from the whole database", whole_md,
                       f"Goals: {GOAL_PROTOCOLS['whole']}; the paper's numbers are those of "
                       f"its test goals, for comparison. {_time_note(whole_rows)}."))
    if controller_rows:
        _, controller_md = write_table(controller_rows, paper, out, name=f"table1_{controller}")
        tables.append((f"## A classical baseline: the `{controller}` controller, not learned",
                       controller_md,
                       f"Goals: {GOAL_PROTOCOLS['test']}; the same episodes as the agents'. "
                       f"A hand-made controller (`dlo_course/jacobian.py`), default "
                       f"settings. {_time_note(controller_rows)}."))
    plot_learning_curves([agent_dir(checkpoints, n) for n in nodes],
                         out=out / "fig4_learning_curves.png",
                         labels=[f"{n} nodes" for n in nodes])
    fig5 = out / "fig5_deformation.png"
    plot_deformation(agent_dir(checkpoints, 4 if 4 in nodes else nodes[0]), fig5, seed=seed,
                     max_steps=max_steps,
                     time_mode=time_mode)
    records = {n: training_record(checkpoints, n) for n in nodes}
    lines = [
        "# Table I, reproduced",
        "",
        f"Episodes per setting: {episodes} (the paper: 1000), at most {max_steps} actions each, "
        f"goal draw seed {seed}, {mpi.size()} MPI rank(s)."
        + ("" if nodes == NODE_COUNTS else
           f" Node counts: {', '.join(map(str, nodes))} only (`--nodes`)."),
        f"Time per action: `{time_mode}` ("
        + ("3 ms of physics per action, as in the authors' code" if time_mode == "code"
           else "0.06 s of physics per action, as in the paper's text") + ").",
        "Databases: " + database_protocols() + ". "
        "A verdict \"above\" or \"below\" means the paper's done % lies outside our 95% "
        "interval.",
        "",
        f"## Training budgets (the paper: 32 agents x 63 episodes x 300 steps = "
        f"{PAPER_TRANSITIONS:,} transitions, gradients summed, under 3.5 h on 32 cores, about "
        f"{PAPER_CORE_HOURS:.0f} core-hours)",
        "",
        "| nodes | ranks | episodes per agent x steps | transitions (share of the paper's) | "
        "wall time (h) | core-hours | gradient reduction | course options | seed | commit |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, rec in records.items():
        wall, ranks, transitions = rec.get("wall_time_h"), rec.get("ranks"), rec.get("transitions")
        share = f" ({transitions / PAPER_TRANSITIONS:.1%})" if transitions else ""
        core_hours = f"{wall * ranks:.2f}" if wall is not None and ranks else "?"
        lines.append(f"| {n} | {ranks or '?'} | {rec.get('episodes_per_agent', '?')} x "
                     f"{rec.get('steps_per_episode', '?')} | {transitions or '?'}{share} | "
                     f"{'?' if wall is None else f'{wall:.2f}'} | {core_hours} | "
                     f"{rec.get('reduce', '?')} | {course_options(rec)} | "
                     f"{rec.get('seed', '?')} | {rec.get('commit', '?')} |")
    lines += ["", "Course options (not in the paper, docs/design.md): input scaling, pre-tanh "
              "penalty, updates per environment step, OU sigma when it differs from 0.3, and "
              "the training levers (hindsight relabelling, no reset between episodes, batch "
              "and buffer sizes, TD3's twin critics, policy delay and target noise, episodes "
              "that end at the goal instead of running all their steps, a training threshold "
              "other than 0.05 m)."]
    for title, path, note in tables:
        lines += ["", title, "", note, "", path.read_text()]
    lines += seeds_section(checkpoints, nodes)
    lines += [f"Files: `{csv_path.name}`, `{md_path.name}`"
              + (", `table1_whole_database.csv`, `table1_whole_database.md`" if whole_rows
                 else "")
              + (f", `table1_{controller}.csv`, `table1_{controller}.md`" if controller_rows
                 else "") + f", `fig4_learning_curves.png`, `{fig5.name}`."]
    report = out / "report.md"
    report.write_text("\n".join(lines) + "\n")
    return report
