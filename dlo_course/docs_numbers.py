"""The result numbers of ``README.md`` and ``docs/design.md``, rendered from the committed
files that hold them, so that the prose never states a number the files do not.

A generated block sits between two markers::

    <!-- table1:begin -->
    ...
    <!-- table1:end -->

and holds exactly what :data:`BLOCKS` renders for its name from the repository's files:

* ``table1``: Table I on the paper's test goals (``docs/reproduction/table1.csv`` beside the
  paper's ``data/paper/table1.csv``), the count of verdicts, the whole-database protocol
  (``docs/reproduction/table1_whole_database.csv``) and the floor of goals met by doing
  nothing (``benchmarks/results/test_goal_floor/README.md``) and the classical controller
  against the agents (``docs/reproduction/table1_jacobian.csv``);
* ``agents``: the shipped agents (``data/checkpoints/nodes*/record.json`` and
  ``config.json``): the preset named in the training command, ranks, episodes,
  transitions, which actor was shipped, the training threshold and episode ending;
* ``ablation``: the table of ``benchmarks/results/ablation/README.md``;
* ``seeds``: Table I's cells over training seeds, the tables of the reports in
  :data:`SEEDS_REPORTS` (``benchmarks/results/seeds/``, ``benchmarks/seeds_table1.py``);
* ``database``: our small database against the authors'
  (``benchmarks/results/database_vs_authors.txt``);
* ``fidelity``: the committed databases against the authors' sweeps, record by record
  (:mod:`dlo_course.fidelity` on ``data/databases/{small,large}.npz``);
* ``tip-reads`` and ``before-after``: what reading the tip with forward kinematics changes,
  and the scene before and after issue 35 (``benchmarks/results/tip_reads.txt``,
  ``scene_before_after.txt``);
* ``scenes``: the agents trained in the old scene, Table I in the scene before issue 35 and
  in its scene (``docs/reproduction/before_issue35/`` and ``before_issue36/``);
* ``speed``: ``benchmarks/results/bench_env.txt`` and ``dlo_train_throughput.txt``;
* ``reproduction-time``: the protocol summary of ``benchmarks/results/reproduction_time.txt``;
* ``exercises`` and ``course-size``: the graded items of every lesson and their points, and the
  course's totals, read from the cells' metadata in ``solutions/``
  (:mod:`dlo_course.grading.notebooks` documents it).

``python -m dlo_course.docs_numbers`` rewrites every block of these files in place after a
retraining or a new report; ``--check`` only reports the blocks that differ (exit status 1).
``tests/test_docs_numbers.py`` fails when a committed block differs from its rendering.

Imports nothing beyond the standard library (no NumPy, torch or PyBullet).
"""

from __future__ import annotations

import csv
import json
import re
import sys
from pathlib import Path
from typing import Callable

REPO_ROOT = Path(__file__).resolve().parent.parent
DOCS = ("README.md", "docs/design.md", "lessons/README.md")
"""The files whose blocks are generated, relative to the repository."""

PAPER_TRANSITIONS = 32 * 63 * 300
"""The paper's training budget per node count: 32 agents x 63 episodes x 300 steps."""

DEFAULT_TRAIN_THRESHOLD = 0.05
"""The environment's threshold when a run's ``env_kwargs`` name none (``task.TRAIN_THRESHOLD``;
repeated here, and checked equal by the test, so that this module imports nothing)."""

_MARKER = re.compile(r"<!-- ([a-z0-9-]+):begin -->\n(.*?)<!-- \1:end -->", re.S)


def _read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _n(x: int) -> str:
    """An integer with thin groups of three digits, as the docs write them: 60 000."""
    return f"{x:,}".replace(",", " ")


def _key(row: dict[str, str]) -> tuple[str, int, str, float]:
    return row["reinit"], int(row["nodes"]), row["database"], float(row["threshold"])


def _pct(x: str | float) -> str:
    return f"{float(x):g}"


def _ours(row: dict[str, str]) -> str:
    return (f"{float(row['done_percent']):.0f} "
            f"({float(row['done_ci_low']):.0f}-{float(row['done_ci_high']):.0f})")


def _paper_rows(root: Path) -> dict[tuple, dict[str, str]]:
    return {_key(r): r for r in _read_csv(root / "data/paper/table1.csv")}


def _test_goal_floor(root: Path) -> dict[int, str]:
    """Share of the 100 small-test episodes (seed 0) within 0.05 m of the goal at the start."""
    text = (root / "benchmarks/results/test_goal_floor/README.md").read_text()
    floor = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 6 and cells[1] == "small-test" and cells[0].isdigit():
            floor[int(cells[0])] = cells[3]
    return floor


def table1_markdown(root: Path = REPO_ROOT) -> str:
    """Table I of the committed report beside the paper's numbers, as Markdown.

    Raises ``ValueError`` when the report's copy of a paper number differs from
    ``data/paper/table1.csv``, or when a setting is missing on either side.
    """
    ours = _read_csv(root / "docs/reproduction/table1.csv")
    paper = _paper_rows(root)
    if {_key(r) for r in ours} != set(paper):
        raise ValueError("docs/reproduction/table1.csv and data/paper/table1.csv name "
                         "different settings")
    by_key = {}
    for r in ours:
        p = float(paper[_key(r)]["done_percent"])
        if abs(float(r["paper_done_percent"]) - p) > 1e-9:
            raise ValueError(f"setting {_key(r)}: the report's paper done % "
                             f"{r['paper_done_percent']} is not data/paper/table1.csv's {p}")
        by_key[_key(r)] = r
    thresholds = sorted({k[3] for k in by_key}, reverse=True)
    episodes = sorted({r["episodes"] for r in ours})
    lines = [
        "| reinit | nodes | goals | " + " | ".join(
            f"ours at {t:g} m (95% CI) | paper | ours vs paper" for t in thresholds) + " |",
        "|---|---|---|" + "---|---|---|" * len(thresholds),
    ]
    seen = []
    for k in by_key:
        if k[:3] not in seen:
            seen.append(k[:3])
    for reinit, nodes, db in seen:
        cells = []
        for t in thresholds:
            r = by_key[(reinit, nodes, db, t)]
            cells += [_ours(r), paper[(reinit, nodes, db, t)]["done_percent"], r["verdict"]]
        lines.append(f"| {reinit} | {nodes} | {db}-test | " + " | ".join(cells) + " |")
    verdicts = [r["verdict"] for r in ours]
    n_above, n_within, n_below = (verdicts.count(v) for v in ("above", "within", "below"))
    lines += [
        "",
        f"- Done % over {', '.join(episodes)} test episodes per setting. The paper's done % is "
        f"**not significantly above ours in {n_above + n_within} of {len(ours)} settings** "
        f"(ours above the paper in {n_above}, the paper within our 95% interval in "
        f"{n_within}, ours below in {n_below}).",
    ]
    whole = _read_csv(root / "docs/reproduction/table1_whole_database.csv")
    cells = []
    for db in ("small", "large"):
        row = [r for r in whole if r["database"] == db and float(r["threshold"]) == thresholds[0]
               and r["reinit"] == "with"]
        row.sort(key=lambda r: int(r["nodes"]))
        cells.append(f"{'/'.join(_pct(r['done_percent']) for r in row)}% of the whole {db} "
                     f"database")
    nodes = "/".join(str(n) for n in sorted({k[1] for k in by_key}))
    lines.append(
        f"- The harder protocol, goals drawn from the whole database (with reinitialisation, "
        f"{thresholds[0]:g} m, {nodes} nodes): {cells[0]}, {cells[1]}.")
    jacobian = {_key(r): r for r in _read_csv(root / "docs/reproduction/table1_jacobian.csv")}
    lower = sum(float(r["done_percent"]) < float(by_key[k]["done_percent"])
                for k, r in jacobian.items())
    lines.append(
        f"- A classical controller, shape servoing with an online Jacobian estimate, on the same "
        f"episodes: below the agents in {lower} of its {len(jacobian)} settings "
        f"(`docs/reproduction/table1_jacobian.md`).")
    lines += _seeds_line(root)
    floor = _test_goal_floor(root)
    lines.append(
        f"- Doing nothing already meets {'/'.join(floor[n] for n in sorted(floor))} of the "
        f"small test episodes at {thresholds[0]:g} m ({'/'.join(str(n) for n in sorted(floor))} "
        f"nodes: they start that close to their goal).")
    return "\n".join(lines) + "\n"


def _preset_of(command: str) -> str:
    m = re.search(r"--preset[ =](\S+)", command)
    if not m:
        raise ValueError(f"no --preset in the training command {command!r}")
    return f"`{m.group(1)}`"


def agents_markdown(root: Path = REPO_ROOT) -> str:
    """The shipped agents of ``data/checkpoints/nodes*``, one row each, from their
    ``record.json`` and ``config.json``."""
    lines = [
        "| agent | preset | ranks | episodes x actions | transitions (of the paper's "
        f"{_n(PAPER_TRANSITIONS)}) | shipped actor | trained at | episodes | wall time |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    dirs = sorted((root / "data/checkpoints").glob("nodes*"), key=lambda p: int(p.name[5:]))
    for d in dirs:
        record = json.loads((d / "record.json").read_text())
        config = json.loads((d / "config.json").read_text())["config"]
        selected = record.get("selected")
        if selected:
            actor = (f"best validated, episode {selected['episode']} "
                     f"({_n(selected['transitions'])} transitions)")
        else:
            actor = "last"
        threshold = config["env_kwargs"].get("threshold", DEFAULT_TRAIN_THRESHOLD)
        ending = "end at the goal" if record.get("stop_at_goal", True) else "run on past the goal"
        # TrainConfig's default (the paper's text) where an old record does not say
        ending += ("; world rebuilt between them" if record.get("reset_between_episodes", True)
                   else "; rod's shape kept between them")
        transitions = record["transitions"]
        lines.append(
            f"| [`{d.name}`](data/checkpoints/{d.name}/record.json) | "
            f"{_preset_of(record['command'])} | {record['ranks']} | "
            f"{record['episodes_per_agent']} x {record['steps_per_episode']} | "
            f"{_n(transitions)} ({100 * transitions / PAPER_TRANSITIONS:.1f}%) | "
            f"{actor} | {threshold:g} m | {ending} | {record['wall_time_h']:.2f} h |")
    return "\n".join(lines) + "\n"


def _table_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("|")]


def ablation_markdown(root: Path = REPO_ROOT) -> str:
    """The ablation's table, as ``benchmarks/ablation.py report`` wrote it."""
    text = (root / "benchmarks/results/ablation/README.md").read_text()
    return "\n".join(_table_lines(text)) + "\n"


SEEDS_INTERVAL = ("mean_done_percent", "seed_ci_low", "seed_ci_high")
"""The columns of ``table1_seeds.csv`` that hold a cell's mean done % over seeds and its
t-interval, in the order :func:`format_done_interval` takes them."""


def format_done_interval(mean: float, low: float, high: float) -> str:
    """A done % over seeds as the reports print it: ``"mean [low, high]"`` to one decimal.

    A t-interval is symmetric, so with seeds that disagree it can reach past 0 or 100 %,
    which no done % can: the printed bounds are clipped to that range (the verdicts use the
    unclipped interval, which gives the same answer against any paper number in it). Shared
    with ``benchmarks/seeds_table1.py``, whose tables the README's seeds line quotes.
    """
    return f"{mean:.1f} [{max(low, 0.0):.1f}, {min(high, 100.0):.1f}]"


def format_row_interval(row: dict[str, str]) -> str:
    """:func:`format_done_interval` of one row of ``table1_seeds.csv`` (or of a node count's
    report CSV), whose values are strings."""
    return format_done_interval(*(float(row[k]) for k in SEEDS_INTERVAL))


def _seeds_line(root: Path) -> list[str]:
    """Table I over training seeds (``benchmarks/results/seeds/table1_seeds.csv``, written by
    ``seeds_table1.py table`` beside its Markdown table) in one line, so that the README's
    Table I, one seed per node count, says how its cells fare over three; nothing while that
    table is not made."""
    path = root / "benchmarks/results/seeds/table1_seeds.csv"
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    nodes = sorted({int(r["nodes"]) for r in rows})
    seeds = sorted({int(r["seeds"]) for r in rows})
    below = [r for r in rows if r["verdict"] == "below"]
    where = "; below: " + ", ".join(
        f"{r['nodes']} nodes, {r['database']} box, {r['reinit']} reinitialisation, "
        f"{float(r['threshold']):g} m ({format_row_interval(r)} "
        f"against {float(r['paper_done_percent']):g})" for r in below) if below else ""
    return [f"- Over {'-'.join(map(str, seeds))} training seeds of each shipped configuration "
            f"({'/'.join(map(str, nodes))} nodes: "
            f"`benchmarks/results/seeds/table1_seeds.md`, mean and t-interval over the seeds): "
            f"the paper's done % is not significantly above ours in "
            f"{len(rows) - len(below)} of {len(rows)} settings{where}."]


SEEDS_REPORTS = (
    ("nodes6_scene35-sigma0.3-e260", "6 nodes, the scene of issue 35, OU sigma 0.3, 260 "
                                     "episodes per agent (the shipped 6-node agent is its seed "
                                     "2, picked by validation)"),
    ("nodes6_scene35-sigma0.3", "6 nodes, the scene of issue 35, OU sigma 0.3, 130 episodes "
                                "per agent"),
    ("nodes6_scene35-sigma0.15", "6 nodes, the scene of issue 35, OU sigma 0.15"),
    ("nodes2_scene35", "2 nodes, the scene of issue 35, the configuration of the 2-node agent "
                       "shipped before (500 episodes per agent, OU sigma 0.15, the best "
                       "validated actor; the shipped 2-node agent is its seed 1, picked by "
                       "validation)"),
    ("nodes4_scene35-reset", "4 nodes, the scene of issue 35, the configuration below with "
                             "the world rebuilt before every training episode (issue 49; the "
                             "shipped 4-node agent is its seed 1, picked by the like-test "
                             "validation)"),
    ("nodes4_scene35", "4 nodes, the scene of issue 35, the configuration of the 4-node agent "
                       "shipped before (260 episodes per agent, OU sigma 0.15, the best "
                       "validated actor, the rod's shape kept between training episodes; its "
                       "seed 2 was the shipped 4-node agent from issue 36 to issue 49)"),
    ("nodes6", "6 nodes, the scene before issue 35 (edge dampers), OU sigma 0.15"),
)
"""The over-seeds reports (``benchmarks/results/seeds/<stem>.md``) the ``seeds`` block shows,
each with its caption, newest scene first; a report not yet made is left out."""


def seeds_markdown(root: Path = REPO_ROOT) -> str:
    """The over-seeds tables of ``benchmarks/seeds_table1.py report`` (:data:`SEEDS_REPORTS`),
    on the paper's test goals."""
    parts = []
    for stem, caption in SEEDS_REPORTS:
        path = root / "benchmarks/results/seeds" / f"{stem}.md"
        if path.is_file():
            parts.append(f"{caption}, on the paper's test goals (`{path.relative_to(root)}`):\n\n"
                         + "\n".join(_table_lines(path.read_text())) + "\n")
    return "\n".join(parts)


def database_markdown(root: Path = REPO_ROOT) -> str:
    """Our small database against the authors' file (``benchmarks/database_vs_authors.py``)."""
    text = (root / "benchmarks/results/database_vs_authors.txt").read_text()
    summary = [line for line in text.splitlines() if line.startswith("mean node distance")]
    return "\n".join(_table_lines(text) + [""] + summary) + "\n"


def fidelity_markdown(root: Path = REPO_ROOT) -> str:
    """The committed databases against the authors' sweeps, record by record
    (:mod:`dlo_course.fidelity`, computed from the files themselves)."""
    from dlo_course.database import load_database
    from dlo_course.fidelity import compare_with_authors

    lines = ["| database | records | mean (mm) | median (mm) | max (mm) | mean per level, "
             "from the initial height down (mm) |", "|---|---|---|---|---|---|"]
    for box in ("small", "large"):
        rows = compare_with_authors(
            load_database(root / "data/databases" / f"{box}.npz").goals(4), box)
        levels = ", ".join(f"{r.mean * 1e3:.1f}" for r in rows[:-1])
        total = rows[-1]
        lines.append(f"| `{box}` | {_n(total.records)} | {total.mean * 1e3:.1f} | "
                     f"{total.median * 1e3:.1f} | {total.max * 1e3:.1f} | {levels} |")
    return "\n".join(lines) + "\n"


def scenes_markdown(root: Path = REPO_ROOT) -> str:
    """The agents trained in the old scene, Table I before and after issue 35's scene, beside
    the paper: ``docs/reproduction/before_issue35/`` against ``before_issue36/`` (both
    protocols; issue 36 replaced the 6-node agent, so the shipped agents' own report, one
    folder up, no longer isolates the scene)."""
    before_dir = root / "docs/reproduction/before_issue35"
    now_dir = root / "docs/reproduction/before_issue36"
    lines = ["| goals | reinit | nodes | database | at 0.05 m: before / now / paper | "
             "at 0.03 m: before / now / paper |", "|---|---|---|---|---|---|"]
    for name, goals in (("table1.csv", "test"), ("table1_whole_database.csv", "whole")):
        before = {_key(r): r for r in _read_csv(before_dir / name)}
        now = {_key(r): r for r in _read_csv(now_dir / name)}
        for reinit, nodes, db in dict.fromkeys(k[:3] for k in now):
            cells = []
            for t in (0.05, 0.03):
                r, b = now.get((reinit, nodes, db, t)), before.get((reinit, nodes, db, t))
                cells.append(" / ".join([_pct(b["done_percent"]) if b else "-",
                                         f"**{_pct(r['done_percent'])}**" if r else "-",
                                         r["paper_done_percent"] if r else "-"]))
            lines.append(f"| {goals} | {reinit} | {nodes} | {db} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n"


def _result_table(name: str) -> Callable[[Path], str]:
    """A block that is the Markdown table of ``benchmarks/results/<name>``."""
    def render(root: Path = REPO_ROOT) -> str:
        return "\n".join(_table_lines((root / "benchmarks/results" / name).read_text())) + "\n"
    render.__doc__ = f"The table of ``benchmarks/results/{name}``."
    return render


def speed_markdown(root: Path = REPO_ROOT) -> str:
    """Actions and transitions per second (``dlo-course bench env``,
    ``benchmarks/dlo_train_throughput.py``)."""
    env = (root / "benchmarks/results/bench_env.txt").read_text()
    rows = {}
    for line in env.splitlines():
        parts = line.split()
        if parts and parts[0] in ("code", "paper") and len(parts) >= 8:
            rows[parts[0]] = parts
    ratio = re.search(r"costs ([\d.]+)x", env).group(1)
    train = (root / "benchmarks/results/dlo_train_throughput.txt").read_text()
    rates = dict(re.findall(r"^(\d) rank\(s\): ([\d.]+) transitions/s", train, re.M))
    scale = re.search(r"2 ranks / 1 rank: ([\d.]+)x", train).group(1)
    code, paper = rows["code"], rows["paper"]
    return "\n".join([
        "| what | number |",
        "|---|---|",
        f"| one environment, `code` time | {code[2]} actions/s; physics {code[3]} of a step, "
        f"IK {code[4]}, reading nodes {code[5]}, observation {code[6]}, rest {code[7]} |",
        f"| one environment, `paper` time | {paper[2]} actions/s ({ratio}x the compute per "
        f"action) |",
        f"| trainer on the rod (4 nodes), 1 rank | {rates['1']} transitions/s |",
        f"| trainer on the rod (4 nodes), 2 ranks | {rates['2']} transitions/s ({scale}x) |",
    ]) + "\n"


def reproduction_time_markdown(root: Path = REPO_ROOT) -> str:
    """Where the default reproduction's minutes go (``benchmarks/reproduction_time.py``)."""
    text = (root / "benchmarks/results/reproduction_time.txt").read_text()
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("protocol"))
    body = [line.rstrip() for line in lines[start:] if line.strip()]
    return "```text\n" + "\n".join(body) + "\n```\n"


def _graded_items(root: Path) -> list[tuple[str, list[tuple[str, int, str]], list[str]]]:
    """(notebook stem, [(name, points, "code", "text" or "choice")], required data files) per
    solution notebook, in the course's order, from the cells' ``dlo_course`` metadata: a
    written answer is "text" (prose, for the instructor) or "choice" (among stated options,
    graded automatically)."""
    lessons = []
    for path in sorted((root / "solutions").glob("[0-9][0-9]_*.ipynb")):
        nb = json.loads(path.read_text(encoding="utf-8"))
        items = []
        for cell in nb["cells"]:
            meta = cell.get("metadata", {}).get("dlo_course") or {}
            if "exercise" in meta and cell["cell_type"] == "code":
                items.append((meta["exercise"], int(meta.get("points", 1)), "code"))
            elif "answer" in meta and cell["cell_type"] == "markdown":
                items.append((meta["answer"], int(meta.get("points", 1)),
                              "choice" if "choices" in meta else "text"))
        needs = nb.get("metadata", {}).get("dlo_course", {}).get("requires", [])
        lessons.append((path.stem, items, list(needs)))
    return lessons


def exercises_markdown(root: Path = REPO_ROOT) -> str:
    """One row per lesson: its exercises and written answers with their points, and the
    data files it needs (``data/...``)."""
    lines = ["| notebook | exercises (points) | points | needs (in `data/`) |", "|---|---|---|---|"]
    for stem, items, needs in _graded_items(root):
        code = ", ".join(f"`{n}` ({p})" for n, p, kind in items if kind == "code")
        text = ", ".join(f"`{n}` ({p}{', a choice' if kind == 'choice' else ''})"
                         for n, p, kind in items if kind in ("text", "choice"))
        graded = code + (f"; written: {text}" if text else "")
        lines.append(f"| `{stem}` | {graded} | {sum(p for _, p, _ in items)} | "
                     f"{', '.join(f'`{n}`' for n in needs)} |")
    return "\n".join(lines) + "\n"


def course_size_markdown(root: Path = REPO_ROOT) -> str:
    """The course's totals: exercises and written answers, and their points (the grader's
    and the instructor's: no pattern gives a written answer points)."""
    items = [item for _, lesson, _ in _graded_items(root) for item in lesson]
    code = [p for _, p, kind in items if kind == "code"]
    text = [p for _, p, kind in items if kind == "text"]
    choice = [p for _, p, kind in items if kind == "choice"]
    automatic = (f"{len(code)} exercises ({sum(code)} points) and {len(choice)} written "
                 f"choices ({sum(choice)} points), graded automatically" if choice else
                 f"{len(code)} exercises ({sum(code)} points, graded automatically)")
    return (f"{automatic}; {len(text)} written answers ({sum(text)} points), given by the "
            f"instructor: {sum(code) + sum(choice) + sum(text)} points.\n")


BLOCKS: dict[str, Callable[[Path], str]] = {
    "exercises": exercises_markdown,
    "course-size": course_size_markdown,
    "table1": table1_markdown,
    "agents": agents_markdown,
    "ablation": ablation_markdown,
    "seeds": seeds_markdown,
    "database": database_markdown,
    "fidelity": fidelity_markdown,
    "tip-reads": _result_table("tip_reads.txt"),
    "scenes": scenes_markdown,
    "before-after": _result_table("scene_before_after.txt"),
    "speed": speed_markdown,
    "reproduction-time": reproduction_time_markdown,
}
"""Every generated block, by the name in its markers."""


def blocks_in(text: str) -> dict[str, str]:
    """The generated blocks of a document, name -> content between the markers."""
    found: dict[str, str] = {}
    for m in _MARKER.finditer(text):
        if m.group(1) in found:
            raise ValueError(f"block {m.group(1)!r} appears twice")
        found[m.group(1)] = m.group(2)
    return found


def render(text: str, root: Path = REPO_ROOT) -> str:
    """``text`` with every generated block replaced by its rendering from ``root``'s files."""
    unknown = set(blocks_in(text)) - set(BLOCKS)
    if unknown:
        raise ValueError(f"unknown generated blocks: {sorted(unknown)}")
    return _MARKER.sub(
        lambda m: f"<!-- {m.group(1)}:begin -->\n{BLOCKS[m.group(1)](root)}"
                  f"<!-- {m.group(1)}:end -->", text)


def stale_blocks(root: Path = REPO_ROOT) -> list[str]:
    """``file: block`` for every generated block that differs from its rendering."""
    stale = []
    for name in DOCS:
        text = (root / name).read_text()
        for block, content in blocks_in(text).items():
            if block not in BLOCKS or content != BLOCKS[block](root):
                stale.append(f"{name}: {block}")
    return stale


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args not in ([], ["--check"]):
        print("usage: python -m dlo_course.docs_numbers [--check]", file=sys.stderr)
        return 2
    if args == ["--check"]:
        stale = stale_blocks()
        for line in stale:
            print(f"stale: {line}")
        return 1 if stale else 0
    for name in DOCS:
        path = REPO_ROOT / name
        text = path.read_text()
        new = render(text)
        if new != text:
            path.write_text(new)
            print(f"rewrote {name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
