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
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dlo_course.paths import CHECKPOINT_DIR, DATA_DIR

PAPER_TABLE = DATA_DIR / "paper" / "table1.csv"
NODES = (2, 4, 6)


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


def table1_cells() -> list[Cell]:
    """The 24 settings in the paper's order."""
    return [Cell(r, n, db, thr) for r in ("with", "without") for n in NODES
            for db in ("small", "large") for thr in (0.05, 0.03)]


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


def checkpoint_dir(root: Path, n_nodes: int) -> Path:
    return Path(root) / f"nodes{n_nodes}"


def train_agents(preset_name: str, out: Path, seed: int = 0) -> Path:
    """Train one agent per node count with a trainer preset; returns the checkpoint root."""
    from dlo_course import mpi
    from dlo_course.trainer import preset, train

    root = Path(out) / "checkpoints"
    for n in NODES:
        config = preset(preset_name, env_kwargs={"n_nodes": n}, seed=seed,
                        out_dir=str(checkpoint_dir(root, n)))
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


def evaluate_cells(checkpoints: Path, episodes: int, max_steps: int, seed: int,
                   time_mode: str = "code", cells: list[Cell] | None = None,
                   protocol: str = "test") -> list[dict]:
    """Evaluate every cell; on rank 0 returns one dict per cell, elsewhere an empty list.

    Cells that differ only by threshold share their episodes when the world is reinitialised
    (:func:`dlo_course.evaluation.evaluate_thresholds`): 12 runs make the 24 cells.
    """
    from tqdm.auto import tqdm

    from dlo_course import mpi
    from dlo_course.evaluation import evaluate_thresholds

    cells = cells or table1_cells()
    groups: dict[tuple, list[Cell]] = {}
    for cell in cells:
        key = (cell.reinit, cell.nodes, cell.database) + (
            () if cell.reinit == "with" else (cell.threshold,))
        groups.setdefault(key, []).append(cell)
    results: dict[Cell, dict] = {}
    for group in tqdm(groups.values(), desc=f"Table I ({protocol} goals)", unit="run",
                      disable=not mpi.is_root()):
        first = group[0]
        by_threshold = evaluate_thresholds(
            checkpoint_dir(checkpoints, first.nodes), goal_source(first.database, protocol),
            [cell.threshold for cell in group], reinitialize=first.reinit == "with",
            episodes=episodes, max_steps=max_steps, seed=seed, n_nodes=first.nodes,
            time_mode=time_mode, show_progress=False)
        for cell in group:
            summary, _ = by_threshold[cell.threshold]
            if summary is not None:
                results[cell] = {"cell": cell, **summary.as_dict()}
    return [results[cell] for cell in cells if cell in results]


def verdict(row: dict, paper_done: float) -> str:
    """Where the paper's done % lies against our 95% interval: "above" (ours is significantly
    above the paper's), "within", or "below"."""
    if paper_done < row["done_ci_low"]:
        return "above"
    if paper_done > row["done_ci_high"]:
        return "below"
    return "within"


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


def training_record(checkpoints: Path, n_nodes: int) -> dict:
    """What an agent's training cost: ranks, episodes, transitions, wall time, seed, commit,
    and the settings that differ between presets. Read from ``record.json`` if present."""
    folder = checkpoint_dir(checkpoints, n_nodes)
    record_file = folder / "record.json"
    if record_file.is_file():
        return json.loads(record_file.read_text())
    return _run_record(folder)


def _run_record(folder: Path) -> dict:
    from dlo_course.learning_curves import read_progress
    from dlo_course.trainer import TrainConfig

    record: dict[str, Any] = {}
    config_file = folder / "config.json"
    if config_file.is_file():
        config = json.loads(config_file.read_text())
        # Through the dataclass, so that a run older than an option reads as its default.
        cfg = TrainConfig.from_dict(config["config"])
        record.update(ranks=config.get("n_agents"), seed=cfg.seed, reduce=cfg.reduce,
                      commit=config.get("commit"), steps_per_episode=cfg.steps_per_episode,
                      updates_per_step=cfg.updates_per_step,
                      normalize_obs=cfg.ddpg.normalize_obs,
                      preactivation_l2=cfg.ddpg.preactivation_l2,
                      noise_sigma=cfg.ddpg.noise_sigma, her_k=cfg.her_k,
                      reset_between_episodes=cfg.reset_between_episodes,
                      batch_size=cfg.ddpg.batch_size, buffer_size=cfg.ddpg.buffer_size,
                      twin_critics=cfg.ddpg.twin_critics, policy_delay=cfg.ddpg.policy_delay,
                      target_noise=cfg.ddpg.target_noise)
    try:
        progress = read_progress(folder)
    except (FileNotFoundError, ValueError):  # no run yet, or not one episode
        return record
    record.update(episodes_per_agent=int(progress["episode"][-1]),
                  transitions=int(progress["transitions"][-1]),
                  wall_time_h=float(progress["wall_time"][-1]) / 3600)
    return record


SHIPPED_FILES = ("actor.pt", "critic.pt", "config.json", "progress.csv")


def _keep_episodes(path: Path, episodes: int) -> None:
    """Rewrite a per-episode CSV with only its rows up to ``episodes``."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = [row for row in reader if int(row["episode"]) <= episodes]
        fields = reader.fieldnames
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


def ship_run(run_dir: Path, dest: Path, actor: str = "latest", **extra: Any) -> Path:
    """Copy a finished run's networks, configuration and learning curve into ``dest`` (e.g.
    ``data/checkpoints/nodes4``) without its bulky resume checkpoints (replay buffers), and
    write ``record.json``: what the training cost (:func:`training_record`) plus ``extra``
    (e.g. ``commit=...`` for runs started before the trainer recorded it).

    Args:
        actor: "latest" ships the run's last actor; "best" the one that did best on the
            validation goals (``best_actor.pt``, runs with ``validate_every`` > 0), recorded
            as ``selected`` in ``record.json``. The cost recorded is the whole run's either way:
            knowing which actor was best took the training after it too.
    """
    run_dir, dest = Path(run_dir), Path(dest)
    if actor not in ("latest", "best"):
        raise ValueError(f"actor must be 'latest' or 'best', got {actor!r}")
    missing = [f for f in SHIPPED_FILES if not (run_dir / f).is_file()]
    if actor == "best" and not (run_dir / "best_actor.pt").is_file():
        missing.append("best_actor.pt (train with validate_every > 0)")
    if missing:
        raise FileNotFoundError(f"{run_dir} is not a finished run: missing {missing}")
    dest.mkdir(parents=True, exist_ok=True)
    for name in SHIPPED_FILES:
        shutil.copy2(run_dir / name, dest / name)
    for name in ("validation.csv", "best.json"):
        if (run_dir / name).is_file():
            shutil.copy2(run_dir / name, dest / name)
        elif (dest / name).exists():
            (dest / name).unlink()  # left from a run shipped here before
    if actor == "best":
        shutil.copy2(run_dir / "best_actor.pt", dest / "actor.pt")
        extra["selected"] = json.loads((run_dir / "best.json").read_text())
    # A run stopped between checkpoints: its networks are the last checkpoint's, so its
    # learning curve and record stop there too.
    latest = run_dir / "checkpoints" / "latest.json"
    if latest.is_file():
        done = int(json.loads(latest.read_text())["episodes_done"])
        if actor == "best":  # a best actor found after the last checkpoint is still real
            done = max(done, int(extra["selected"]["episode"]))
        for name in ("progress.csv", "validation.csv"):
            if (dest / name).is_file():
                _keep_episodes(dest / name, done)
    record = {**_run_record(dest), **{k: v for k, v in extra.items() if v is not None}}
    (dest / "record.json").write_text(json.dumps(record, indent=2) + "\n")
    return dest


def database_protocols() -> str:
    """How each database was recorded, for the report (e.g. "small: authors_sweep, ...")."""
    from dlo_course.database import BOXES, load_database

    return ", ".join(f"{name}: {load_database(name).protocol} protocol" for name in BOXES)


def plot_deformation(checkpoints: Path, out: Path, n_nodes: int = 4, seed: int = 0,
                     max_steps: int = 30, time_mode: str = "code") -> Path:
    """The paper's Fig. 5: the agent deforms the rod to a goal outside its training box."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dlo_course.database import BOXES, load_database
    from dlo_course.env import DLOShapeEnv
    from dlo_course.evaluation import load_actor, play_episode
    from dlo_course.mesh import selected_nodes
    from dlo_course.plots import plot_rod

    actor, n_nodes = load_actor(checkpoint_dir(checkpoints, n_nodes), n_nodes)
    large = load_database("large")
    goals = large.goals(n_nodes)
    # Goals the sweep recorded with the tip outside the training box.
    outside = np.flatnonzero(~BOXES["small"].contains(large.meta["offsets"]))
    goal_index = int(np.random.default_rng(seed).choice(outside))
    env = DLOShapeEnv(n_nodes=n_nodes, goals=goals, render_mode="rgb_array",
                      time_mode=time_mode)
    ids = list(selected_nodes(n_nodes))
    try:
        obs, info = env.reset(options={"goal_index": goal_index})
        start_nodes, start_image = env.scene.node_positions(), env.render()
        _, steps, info = play_episode(actor, env, obs, max_steps)
        end_nodes, end_image = env.scene.node_positions(), env.render()
    finally:
        env.close()

    fig = plt.figure(figsize=(14, 4.8))
    ax = fig.add_subplot(1, 3, 1)
    ax.imshow(start_image)
    ax.set_title("start (blue: P_c, red: P_d)")
    ax.axis("off")
    ax = fig.add_subplot(1, 3, 2)
    ax.imshow(end_image)
    ax.set_title(f"after {steps} actions: mean distance {info['distance']:.3f} m")
    ax.axis("off")
    ax = fig.add_subplot(1, 3, 3, projection="3d")
    plot_rod(ax, start_nodes, color="grey", label="initial shape")
    plot_rod(ax, end_nodes, selected=ids, goal=goals[goal_index],
             label="final shape")
    # True proportions: a 1.55 m rod bent by tens of centimetres; matplotlib's default cube
    # stretches the sideways bend until it is unreadable.
    points = np.concatenate([start_nodes, end_nodes, goals[goal_index]])
    ax.set_box_aspect(np.maximum(np.ptp(points, axis=0), 0.05))
    ax.set_title(f"{n_nodes} nodes, large-database goal {goal_index}\n"
                 f"(outside the training box)")
    ax.legend(loc="upper left")
    fig.tight_layout()
    path = Path(out) / "fig5_deformation.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def course_options(record: dict) -> str:
    """The course options a training used, in words ("none" for the paper's DDPG)."""
    from dlo_course.ddpg import DDPGConfig
    from dlo_course.trainer import TrainConfig

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
    return ", ".join(parts) or "none"


WHOLE_DATABASE_CELLS = {"with": "with", "all": None, "none": ()}
"""Which cells the whole-database table covers: those "with" reinitialisation, all, or none."""
PAPER_CORE_HOURS = 32 * 3.5  # 32 cores for under 3.5 h
PAPER_TRANSITIONS = 32 * 63 * 300


def reproduce(out: Path, checkpoints: Path | None = None, episodes: int = 100,
              max_steps: int = 30, seed: int = 0, train_preset: str | None = None,
              time_mode: str = "code", whole_database: str = "with") -> Path | None:
    """Regenerate Table I and Figs. 4-5 (see the module docstring); returns the report path
    on rank 0.

    Args:
        whole_database: which cells also get the harder protocol, goals drawn from the whole
            database: "with" (the 12 cells with reinitialisation), "all" or "none".
    """
    import time

    from dlo_course import mpi
    from dlo_course.learning_curves import plot_learning_curves

    if whole_database not in WHOLE_DATABASE_CELLS:
        raise ValueError(f"whole_database must be one of {sorted(WHOLE_DATABASE_CELLS)}")
    out = Path(out)
    paper = read_paper_table()
    if train_preset is not None:
        checkpoints = train_agents(train_preset, out, seed)
    checkpoints = Path(checkpoints or CHECKPOINT_DIR)
    start = time.perf_counter()
    rows = evaluate_cells(checkpoints, episodes, max_steps, seed, time_mode, protocol="test")
    test_minutes = (time.perf_counter() - start) / 60
    scope = WHOLE_DATABASE_CELLS[whole_database]
    whole_cells = [c for c in table1_cells() if scope is None or c.reinit == scope]
    whole_rows = (evaluate_cells(checkpoints, episodes, max_steps, seed, time_mode,
                                 cells=whole_cells, protocol="whole") if whole_cells else [])
    whole_minutes = (time.perf_counter() - start) / 60 - test_minutes
    if not mpi.is_root():
        return None
    csv_path, md_path = write_table(rows, paper, out)
    tables = [("## Table I: ours beside the paper's, on the paper's test goals", md_path,
               f"Goals: {GOAL_PROTOCOLS['test']}. {test_minutes:.0f} min on "
               f"{mpi.size()} rank(s).")]
    if whole_rows:
        _, whole_md = write_table(whole_rows, paper, out, name="table1_whole_database")
        tables.append(("## The harder protocol: goals from the whole database", whole_md,
                       f"Goals: {GOAL_PROTOCOLS['whole']}; the paper's numbers are those of "
                       f"its test goals, for comparison. {whole_minutes:.0f} min."))
    import matplotlib

    matplotlib.use("Agg")
    runs = [checkpoint_dir(checkpoints, n) for n in NODES]
    fig = plot_learning_curves(runs, out=out / "fig4_learning_curves.png",
                               labels=[f"{n} nodes" for n in NODES])
    import matplotlib.pyplot as plt

    plt.close(fig)
    fig5 = plot_deformation(checkpoints, out, seed=seed, max_steps=max_steps,
                            time_mode=time_mode)
    records = {n: training_record(checkpoints, n) for n in NODES}
    lines = [
        "# Table I, reproduced",
        "",
        f"Episodes per setting: {episodes} (the paper: 1000), at most {max_steps} actions each, "
        f"goal draw seed {seed}, {mpi.size()} MPI rank(s).",
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
              "and buffer sizes, TD3's twin critics, policy delay and target noise)."]
    for title, path, note in tables:
        lines += ["", title, "", note, "", path.read_text()]
    lines += [f"Files: `{csv_path.name}`, `{md_path.name}`"
              + (", `table1_whole_database.csv`, `table1_whole_database.md`" if whole_rows
                 else "") + f", `fig4_learning_curves.png`, `{fig5.name}`."]
    report = out / "report.md"
    report.write_text("\n".join(lines) + "\n")
    return report
