"""Every figure of the course (matplotlib, headless-safe), after the paper's:

* Fig. 3, the deformation boxes and the recorded tip positions: :func:`plot_databases`;
* Fig. 4, learning curves of training runs: :func:`plot_learning_curves` (and averaged
  over seeds: :func:`seed_groups`, :func:`seed_curve`);
* Fig. 5, an agent deforming the rod to a goal outside its training box:
  :func:`plot_deformation`;
* an episode's first and last frames, and all of them as a GIF (and an MP4 where an encoder
  is installed), each frame captioned: :func:`plot_episode_frames`, :func:`caption_frame`,
  :func:`save_gif`, :func:`save_mp4` (``dlo-course demo``);
* the pieces: :func:`plot_rod`, :func:`draw_box`.

The figures made here are :class:`matplotlib.figure.Figure` objects outside pyplot (except
Fig. 3's, kept on pyplot for the lessons that show it): nothing needs a display or a backend
switch, and nothing has to be closed.
"""

from __future__ import annotations

import json
from itertools import product
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from dlo_course.database import BOXES, Box, load_database
from dlo_course.evaluation import load_actor, play_episode
from dlo_course.mesh import N_RINGS, node_of_ring, selected_nodes
from dlo_course.rundir import CONFIG_FILE, read_progress


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
    line = nodes[[node_of_ring(k) for k in range(N_RINGS)]]
    ax.plot(*line.T, color=color, lw=2, label=label)
    if len(selected):
        ax.scatter(*nodes[list(selected)].T, marker="x", color="blue", s=50)
    if goal is not None:
        ax.scatter(*np.asarray(goal).T, marker="x", color="red", s=50)


# --- Fig. 4: learning curves ---


def run_label(run_dir: str | Path) -> str:
    """A legend label: the directory's name and, from its ``config.json``, e.g.
    "paper_n2 (DLOShape-v0, n_nodes=2, 32 agents)"."""
    try:
        info: dict[str, Any] = json.loads((Path(run_dir) / CONFIG_FILE).read_text())
    except (OSError, ValueError):
        return Path(run_dir).name
    config = info["config"]
    kwargs = ", ".join(f"{k}={v}" for k, v in config.get("env_kwargs", {}).items())
    agents = info.get("n_agents", 1)
    details = ", ".join(p for p in (config["env_id"], kwargs,
                                    f"{agents} agent{'s' if agents != 1 else ''}") if p)
    return f"{Path(run_dir).name} ({details})"


X_AXES = {"episode": "episode (per agent)", "transitions": "transitions (all agents)"}
"""What a learning curve can be drawn against: ``progress.csv`` columns, and their labels."""

SEED_FREE_FIELDS = ("seed", "out_dir", "episodes", "checkpoint_every", "torch_threads",
                    "expected_agents")
"""Configuration fields that may differ between runs averaged together (:func:`seed_groups`):
the seed, and fields that change where and how long a run is kept, not what it learns."""


def seed_groups(run_dirs: Sequence[str | Path]) -> list[list[Path]]:
    """The runs grouped by configuration: runs whose ``config.json`` differ only in
    :data:`SEED_FREE_FIELDS` (the seed, mainly), with the same number of agents, share a
    group. Groups and their runs keep the order of ``run_dirs``; a run without a readable
    configuration is a group of its own."""
    from dlo_course.config import TrainConfig

    groups: dict[str, list[Path]] = {}
    for run_dir in map(Path, run_dirs):
        try:
            info = json.loads((run_dir / CONFIG_FILE).read_text())
            # Through the dataclass, so that a run older than an option reads as its default.
            config = TrainConfig.from_dict(info["config"]).to_dict()
            key = json.dumps({"config": {k: v for k, v in config.items()
                                         if k not in SEED_FREE_FIELDS},
                              "n_agents": info.get("n_agents", 1)}, sort_keys=True)
        except (OSError, ValueError, TypeError, KeyError):
            key = f"alone: {run_dir.resolve()}"
        groups.setdefault(key, []).append(run_dir)
    return list(groups.values())


def seed_curve(progresses: Sequence[dict[str, np.ndarray]], x: str = "episode",
               points: int = 200) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean episode reward over seeds: (x grid, mean, standard deviation) over the range of
    ``x`` that every run covers (each run's mean over its agents, ``reward_mean``).

    Runs make different numbers of transitions per episode, so against ``"transitions"``
    each run is interpolated onto ``points`` common values; against ``"episode"`` the grid
    is the episodes themselves. One run gives a standard deviation of 0."""
    if x not in X_AXES:
        raise ValueError(f"x must be one of {list(X_AXES)}, got {x!r}")
    first = max(float(p[x][0]) for p in progresses)
    last = min(float(p[x][-1]) for p in progresses)
    if x == "episode":
        grid = np.arange(first, last + 1)
    else:
        grid = np.linspace(first, last, points) if last > first else np.array([first])
    curves = np.array([np.interp(grid, p[x], p["reward_mean"]) for p in progresses])
    spread = curves.std(axis=0, ddof=1) if len(curves) > 1 else np.zeros_like(grid)
    return grid, curves.mean(axis=0), spread


def plot_learning_curves(run_dirs: Sequence[str | Path], out: str | Path | None = None,
                         labels: Sequence[str] | None = None, ax: Axes | None = None,
                         x: str = "episode", aggregate_seeds: bool = False) -> Figure:
    """The paper's Fig. 4: mean episode reward per episode of each run, with its min-max
    band over the agents (the paper draws the mean, unsmoothed).

    Args:
        run_dirs: run directories or trained agents (each with a ``progress.csv``).
        out: image file to write (PNG, PDF, SVG...), or ``None``.
        labels: legend labels, one per run (per group of seeds with ``aggregate_seeds``;
            default: from each run's configuration).
        ax: axes to draw into (default: a new figure).
        x: "episode" (per agent, as in the paper) or "transitions" (all agents together).
        aggregate_seeds: one curve per group of runs that differ only by seed
            (:func:`seed_groups`): the mean over the seeds, with a band of one standard
            deviation over them (:func:`seed_curve`).

    Returns:
        The figure.
    """
    if x not in X_AXES:
        raise ValueError(f"x must be one of {list(X_AXES)}, got {x!r}")
    groups = seed_groups(run_dirs) if aggregate_seeds else [[Path(r)] for r in run_dirs]
    if labels is not None and len(labels) != len(groups):
        unit = "group of seeds" if aggregate_seeds else "run directory"
        raise ValueError(f"give one label per {unit} ({len(groups)}), got {len(labels)}")
    if ax is None:
        fig = Figure(figsize=(6.4, 4.0), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    for i, group in enumerate(groups):
        progresses = [read_progress(run_dir) for run_dir in group]
        if aggregate_seeds:
            label = labels[i] if labels is not None else \
                f"{run_label(group[0])}, {len(group)} seed{'s' if len(group) != 1 else ''}"
            grid, mean, spread = seed_curve(progresses, x)
            low, high = mean - spread, mean + spread
        else:
            p = progresses[0]
            label = labels[i] if labels is not None else run_label(group[0])
            grid, mean, low, high = p[x], p["reward_mean"], p["reward_min"], p["reward_max"]
        (line,) = ax.plot(grid, mean, label=label)
        # With a single agent (or seed) the band is empty: nothing to draw.
        ax.fill_between(grid, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
    ax.set_xlabel(X_AXES[x])
    ax.set_ylabel("episode reward")
    ax.set_title("mean over seeds (line), one standard deviation (band)" if aggregate_seeds
                 else "mean over agents (line), min to max (band)", fontsize="medium")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, out, dpi=150)
    return fig


# --- rendered episodes: Fig. 5 and the demo ---


def _show_image(ax: Axes, image: np.ndarray, title: str) -> None:
    ax.imshow(image)
    ax.set_title(title)
    ax.axis("off")


def _save(fig: Figure, out: str | Path | None, dpi: int) -> None:
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=dpi)


def plot_deformation(agent: str | Path, out: str | Path | None = None, seed: int = 0,
                     max_steps: int = 30, time_mode: str = "code") -> Figure:
    """The paper's Fig. 5: a trained agent deforms the rod to a goal of the large database
    that the sweep recorded with the tip outside the training (small) box.

    Args:
        agent: a trained agent (:func:`dlo_course.evaluation.load_actor`); its number of
            nodes is read from its actor.
        out: image file to write, or ``None``.
        seed: chooses the goal among those outside the small box.
        max_steps: at most this many actions.
        time_mode: the environment's time per action ("code" or "paper").

    Returns:
        The figure: the rendered start and end, and both rod shapes in 3D with P_c and P_d.
    """
    from dlo_course.env import make_env  # imports PyBullet: only when needed

    actor, n_nodes = load_actor(agent)
    large = load_database("large")
    goals = large.goals(n_nodes)
    outside = np.flatnonzero(~BOXES["small"].contains(large.meta["offsets"]))
    goal_index = int(np.random.default_rng(seed).choice(outside))
    env = make_env(n_nodes=n_nodes, goals=goals, render_mode="rgb_array", time_mode=time_mode)
    try:
        obs, info = env.reset(options={"goal_index": goal_index})
        start_nodes, start_image = env.unwrapped.scene.node_positions(), env.render()
        _, steps, info = play_episode(actor, env, obs, max_steps)
        end_nodes, end_image = env.unwrapped.scene.node_positions(), env.render()
    finally:
        env.close()

    fig = Figure(figsize=(14, 4.8))
    _show_image(fig.add_subplot(1, 3, 1), start_image, "start (blue: P_c, red: P_d)")
    _show_image(fig.add_subplot(1, 3, 2), end_image,
                f"after {steps} actions: mean distance {info['distance']:.3f} m")
    ax = fig.add_subplot(1, 3, 3, projection="3d")
    plot_rod(ax, start_nodes, color="grey", label="initial shape")
    plot_rod(ax, end_nodes, selected=list(selected_nodes(n_nodes)), goal=goals[goal_index],
             label="final shape")
    # True proportions: a 1.55 m rod bent by tens of centimetres; matplotlib's default cube
    # stretches the sideways bend until it is unreadable.
    points = np.concatenate([start_nodes, end_nodes, goals[goal_index]])
    ax.set_box_aspect(np.maximum(np.ptp(points, axis=0), 0.05))
    ax.set_title(f"{n_nodes} nodes, large-database goal {goal_index}\n"
                 f"(outside the training box)")
    ax.legend(loc="upper left")
    fig.tight_layout()
    _save(fig, out, dpi=110)
    return fig


def plot_episode_frames(first: np.ndarray, last: np.ndarray, titles: tuple[str, str],
                        suptitle: str, out: str | Path | None = None) -> Figure:
    """An episode's first and last rendered frames, side by side.

    Args:
        first, last: (H, W, 3) uint8 images (``env.render()``).
        titles: one title per frame.
        suptitle: the figure's title.
        out: image file to write, or ``None``.
    """
    fig = Figure(figsize=(10, 3.9))
    for k, (frame, title) in enumerate(zip((first, last), titles)):
        _show_image(fig.add_subplot(1, 2, k + 1), frame, title)
    fig.suptitle(suptitle)
    fig.tight_layout()
    _save(fig, out, dpi=100)
    return fig


def save_gif(frames: list[np.ndarray], path: str | Path, fps: int = 10,
             hold: Sequence[int] = (), hold_seconds: float = 1.5) -> Path:
    """Write RGB frames (H, W, 3) uint8 as an animated GIF (Pillow ships with matplotlib).

    Args:
        hold: indices of frames shown for ``hold_seconds`` instead of one frame's time, e.g.
            the last frame of each episode, so that a viewer can read where it ended.
    """
    from PIL import Image  # Pillow: a dependency of matplotlib, so always installed

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(f) for f in frames]
    durations = [int(1000 / fps)] * len(frames)
    for k in hold:
        durations[k] = int(1000 * hold_seconds)
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations,
                   loop=0)
    return path


def caption_frame(frame: np.ndarray, lines: Sequence[str]) -> np.ndarray:
    """A rendered frame with ``lines`` of text on a white band above it (the demo writes the
    mean node distance on every frame this way).

    A band rather than text over the picture: at small sizes any corner of the camera's view
    holds part of the robot, and the caption must hide nothing. The font scales with the
    frame's height, and the band's height depends only on that and the number of lines, so
    every frame of a video gets the same size.

    Returns:
        (H + band, W, 3) uint8.
    """
    from PIL import Image, ImageDraw, ImageFont

    frame = np.asarray(frame, dtype=np.uint8)
    height, width = frame.shape[:2]
    size = max(8, height // 24)
    try:
        font = ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: one bitmap size only
        font = ImageFont.load_default()
    margin = max(2, size // 3)
    line_height = size + margin
    band = Image.new("RGB", (width, 2 * margin + line_height * len(lines)), "white")
    draw = ImageDraw.Draw(band)
    for k, line in enumerate(lines):
        draw.text((margin, margin + k * line_height), line, font=font, fill="black")
    return np.concatenate([np.asarray(band), frame], axis=0)


def video_encoder() -> str | None:
    """The ffmpeg program to write MP4 with: one on the ``PATH``, else the one the optional
    ``imageio-ffmpeg`` package brings; None if neither is installed (the course does not
    depend on either: a GIF is always written)."""
    import shutil

    found = shutil.which("ffmpeg")
    if found:
        return found
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    try:
        return imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError:  # the package without its binary
        return None


def save_mp4(frames: list[np.ndarray], path: str | Path, fps: int = 10, hold: Sequence[int] = (),
             hold_seconds: float = 1.5, encoder: str | None = None) -> Path | None:
    """Write RGB frames (H, W, 3) uint8 as an H.264 MP4 through ffmpeg, if there is one.

    Args:
        hold: indices of frames repeated to last ``hold_seconds`` (see :func:`save_gif`).
        encoder: the ffmpeg program; default :func:`video_encoder`.

    Returns:
        the path written, or None when no encoder is installed.
    """
    import subprocess

    encoder = encoder or video_encoder()
    if encoder is None:
        return None
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    height, width = frames[0].shape[:2]
    repeats = [1] * len(frames)
    for k in hold:
        repeats[k] = max(1, round(hold_seconds * fps))
    command = [encoder, "-y", "-loglevel", "error",
               "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{width}x{height}",
               "-r", str(fps), "-i", "-",
               # H.264 in yuv420p needs even sides; players outside ffmpeg need yuv420p.
               "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-c:v", "libx264",
               "-pix_fmt", "yuv420p", str(path)]
    stream = b"".join(np.ascontiguousarray(f, dtype=np.uint8).tobytes() * n
                      for f, n in zip(frames, repeats))
    result = subprocess.run(command, input=stream, capture_output=True, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"ffmpeg could not write {path}: "
                           f"{result.stderr.decode(errors='replace').strip()}")
    return path
