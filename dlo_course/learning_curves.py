"""Learning curves of training runs, drawn like the paper's Fig. 4.

The paper plots, for each number of controlled nodes, the average episode reward of its 32
agents against the episode number, unsmoothed. We draw the same mean curve and, as a band
around it, the range (min to max) of the agents' rewards in that episode.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator


def read_progress(run_dir: str | Path) -> dict[str, np.ndarray]:
    """The columns of a run's ``progress.csv`` as float arrays (empty cells become NaN)."""
    path = Path(run_dir) / "progress.csv"
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: is {run_dir} a training run directory?")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path} has no episode yet")
    return {key: np.array([float(r[key]) if r[key] != "" else np.nan for r in rows])
            for key in rows[0]}


def run_label(run_dir: str | Path) -> str:
    """A legend label: the directory's name and, from its ``config.json``, e.g.
    "paper_n2 (DLOShape-v0, n_nodes=2, 32 agents)"."""
    try:
        info: dict[str, Any] = json.loads((Path(run_dir) / "config.json").read_text())
    except (OSError, ValueError):
        return Path(run_dir).name
    config = info["config"]
    kwargs = ", ".join(f"{k}={v}" for k, v in config.get("env_kwargs", {}).items())
    agents = info.get("n_agents", 1)
    details = ", ".join(p for p in (config["env_id"], kwargs,
                                    f"{agents} agent{'s' if agents != 1 else ''}") if p)
    return f"{Path(run_dir).name} ({details})"


def plot_learning_curves(run_dirs: Sequence[str | Path], out: str | Path | None = None,
                         labels: Sequence[str] | None = None, ax: Axes | None = None) -> Figure:
    """Mean episode reward per episode of each run, with its min-max band over agents.

    Args:
        run_dirs: training run directories (each with a ``progress.csv``).
        out: image file to write (PNG, PDF, SVG...), or ``None``.
        labels: legend labels, one per run (default: from each run's configuration).
        ax: axes to draw into (default: a new figure).

    Returns:
        The figure.
    """
    if labels is not None and len(labels) != len(run_dirs):
        raise ValueError("give one label per run directory")
    if ax is None:
        fig = Figure(figsize=(6.4, 4.0), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    for i, run_dir in enumerate(run_dirs):
        p = read_progress(run_dir)
        label = labels[i] if labels is not None else run_label(run_dir)
        (line,) = ax.plot(p["episode"], p["reward_mean"], label=label)
        # With a single agent the band is empty (min = max = mean): nothing to draw.
        ax.fill_between(p["episode"], p["reward_min"], p["reward_max"], color=line.get_color(),
                        alpha=0.2, linewidth=0)
    ax.set_xlabel("episode (per agent)")
    ax.set_ylabel("episode reward")
    ax.set_title("mean over agents (line), min to max (band)", fontsize="medium")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(alpha=0.3)
    ax.legend()
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=150)
    return fig
