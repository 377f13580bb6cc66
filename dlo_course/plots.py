"""Figures of the environment and the databases (matplotlib, headless-safe)."""

from __future__ import annotations

from itertools import product
from pathlib import Path

import numpy as np

from dlo_course.database import BOXES, Box, load_database


def _box_edges(low: np.ndarray, high: np.ndarray):
    """The 12 edges of an axis-aligned box as pairs of corner points."""
    corners = np.array(list(product(*zip(low, high))))
    for i, j in product(range(8), range(8)):
        if i < j and np.count_nonzero(corners[i] != corners[j]) == 1:
            yield corners[i], corners[j]


def draw_box(ax, box: Box, origin: np.ndarray, **style) -> None:
    """Draw ``box`` (offsets from ``origin``) as a wireframe on a 3D axis."""
    for a, b in _box_edges(origin + np.asarray(box.low), origin + np.asarray(box.high)):
        ax.plot(*zip(a, b), **style)


def plot_databases(out: str | Path | None = None, names=("small", "large")):
    """The paper's Fig. 3: each box (red) and the tip positions recorded in it (dots).

    Returns the matplotlib Figure; saves it to ``out`` when given.
    """
    import matplotlib

    if out is not None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(5.5 * len(names), 5))
    for k, name in enumerate(names):
        db = load_database(name)
        origin = np.asarray(db.meta["initial_tip"])
        ax = fig.add_subplot(1, len(names), k + 1, projection="3d")
        ax.scatter(*db.tip.T, s=3, c=db.tip[:, 2], cmap="viridis", depthshade=False)
        draw_box(ax, BOXES[name], origin, color="red", lw=1.2)
        ax.scatter(*origin, marker="x", color="black", s=40, label="initial tip")
        size = BOXES[name].size
        ax.set_title(f"{name} box {size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} m\n"
                     f"{len(db)} deformations")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.legend(loc="upper left")
    fig.tight_layout()
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120)
    return fig


def plot_rod(ax, nodes: np.ndarray, selected=(), goal=None, color="green", label=None):
    """Draw a rod shape on a 3D axis: its +x surface line, selected nodes (blue crosses) and
    desired positions (red crosses), as in the paper's figures.

    Args:
        nodes: (200, 3) node positions.
        selected: indices of the selected nodes P_c.
        goal: (m, 3) desired positions P_d, or None.
    """
    from dlo_course.mesh import N_RINGS, node_of_ring

    line = nodes[[node_of_ring(k) for k in range(N_RINGS)]]
    ax.plot(*line.T, color=color, lw=2, label=label)
    if len(selected):
        ax.scatter(*nodes[list(selected)].T, marker="x", color="blue", s=50)
    if goal is not None:
        ax.scatter(*np.asarray(goal).T, marker="x", color="red", s=50)
