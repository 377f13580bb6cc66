"""How close the course's sweep is to the authors' own: record by record, level by level.

The authors published the databases their generator wrote (4 nodes, the small and the large
box; ``data/paper/authors_sweeps/``). A database recorded with the authors' sweep
(:func:`dlo_course.database.authors_sweep`) has the same records in the same order, so the two
can be compared goal by goal: for record k, the mean distance between our 4 nodes and theirs.
That is a much stricter check of the physics than comparing the databases' statistics: a scene
whose rod bends a little differently drifts further from theirs at every move of the sweep.

    from dlo_course.fidelity import compare_with_authors
    rows = compare_with_authors(load_database("small").goals(4), "small")
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dlo_course.database import BOXES, sweep_levels
from dlo_course.paths import DATA_DIR

AUTHORS_SWEEPS_DIR = DATA_DIR / "paper" / "authors_sweeps"
AUTHORS_NODES = 4
"""The authors' published sweeps hold 4 nodes: rings 26, 23, 18 and 15 (``selected_nodes(4)``)."""


def authors_sweep_path(box: str) -> Path:
    if box not in BOXES:
        raise ValueError(f"box must be one of {sorted(BOXES)}, got {box!r}")
    return AUTHORS_SWEEPS_DIR / f"{box}_4nodes.txt"


def load_authors_sweep(box: str) -> np.ndarray:
    """(N, 4, 3) the authors' recorded node positions (m, world frame) for ``box``: 930 records
    for the small box, 2 651 for the large, in the order of their sweep."""
    path = authors_sweep_path(box)
    if not path.is_file():
        raise FileNotFoundError(f"missing {path}: the authors' {box} sweep (see "
                                f"{AUTHORS_SWEEPS_DIR / 'README.md'})")
    rows = np.loadtxt(path, ndmin=2)
    if rows.shape[1] != 4 or len(rows) % AUTHORS_NODES:
        raise ValueError(f"{path} should hold lines 'node_id x y z', 4 per record, "
                         f"got shape {rows.shape}")
    return rows[:, 1:4].reshape(-1, AUTHORS_NODES, 3)


def record_distances(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """(K,) mean node distance (m) of record k in ``ours`` to record k in ``theirs``.

    Args:
        ours: (K, 4, 3) node positions, the first K records of a sweep (a partial recording
            is compared with the start of the authors' file).
        theirs: (N, 4, 3) with N >= K, the authors' records.
    """
    ours, theirs = np.asarray(ours, dtype=np.float64), np.asarray(theirs, dtype=np.float64)
    if ours.ndim != 3 or ours.shape[1:] != theirs.shape[1:]:
        raise ValueError(f"ours {ours.shape} and theirs {theirs.shape} must both be "
                         "(records, 4, 3)")
    if len(ours) > len(theirs):
        raise ValueError(f"{len(ours)} records, but the authors' file has {len(theirs)}")
    return np.linalg.norm(ours - theirs[:len(ours)], axis=2).mean(axis=1)


@dataclass(frozen=True)
class LevelFidelity:
    """Record-by-record distances (m) over one sweep level, or over all ("all")."""

    level: str
    records: int
    mean: float
    median: float
    max: float


def level_fidelity(distances: np.ndarray, box: str) -> list[LevelFidelity]:
    """Mean, median and maximum of ``distances`` (K,) per sweep level of ``box`` (level 0 at
    the initial height), then over all K records."""
    distances = np.asarray(distances, dtype=np.float64)
    levels = sweep_levels(BOXES[box])[:len(distances)]

    def row(name: str, d: np.ndarray) -> LevelFidelity:
        return LevelFidelity(name, len(d), float(d.mean()), float(np.median(d)), float(d.max()))

    rows = [row(str(level), distances[levels == level]) for level in np.unique(levels)]
    return rows + [row("all", distances)]


def compare_with_authors(goals: np.ndarray, box: str) -> list[LevelFidelity]:
    """Per-level fidelity of our 4-node records ``goals`` (K, 4, 3) to the authors' ``box``."""
    return level_fidelity(record_distances(goals, load_authors_sweep(box)), box)


def fidelity_markdown(rows: list[LevelFidelity]) -> str:
    """A Markdown table of :func:`level_fidelity`'s rows, in millimetres."""
    lines = ["| level | records | mean (mm) | median (mm) | max (mm) |", "|---|---|---|---|---|"]
    for r in rows:
        name = "**all**" if r.level == "all" else r.level
        lines.append(f"| {name} | {r.records} | {r.mean * 1e3:.1f} | {r.median * 1e3:.1f} | "
                     f"{r.max * 1e3:.1f} |")
    return "\n".join(lines)
