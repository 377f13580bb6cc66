"""Deformation databases: the goal shapes of the paper (Section V-C, Fig. 3).

The robot sweeps its tip through a box of offsets from the initial tip position, in a
boustrophedon (snake) order, and after every move records the tip position and the positions
of all 200 mesh nodes. Any node selection (2, 4 or 6 nodes) is then a view of the same file:
``load_database("small").goals(4)`` has shape (N, 4, 3).

Grid and count (FACTS.md): a box with divisions (nx, ny, nz) has steps size / (n + 1). Each
z level (nz + 1 of them, from one step below the start down to the bottom of the box) is
reached by a descent, which is recorded, and then swept over (nx + 2) x (ny + 2) grid points
covering the box's full x and y extent, each recorded. That is
(nz + 1) * (1 + (nx + 2) * (ny + 2)) deformations: 930 for the small box, 2651 for the large,
the paper's counts. Consecutive levels sweep in opposite directions, so each level after the
first starts at the xy point where its descent ended: that tip position is recorded twice,
a little more settled the second time (5 and 10 repeats in the small and large databases).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dlo_course.mesh import selected_nodes
from dlo_course.paths import DATABASE_DIR


@dataclass(frozen=True)
class Box:
    """A deformation box: offsets (m) from the initial tip position, and grid divisions."""

    name: str
    low: tuple[float, float, float]
    high: tuple[float, float, float]
    divisions: tuple[int, int, int]

    @property
    def size(self) -> np.ndarray:
        return np.subtract(self.high, self.low)

    def contains(self, offsets: np.ndarray) -> np.ndarray:
        """(N,) bool: which of the (N, 3) tip offsets lie in the box, borders included."""
        offsets = np.asarray(offsets, dtype=np.float64)
        return np.all((offsets >= self.low) & (offsets <= self.high), axis=-1)

    @property
    def expected_count(self) -> int:
        nx, ny, nz = self.divisions
        return (nz + 1) * (1 + (nx + 2) * (ny + 2))


BOXES = {
    # Training box: 0.15 x 0.5 x 0.25 m.
    "small": Box("small", (-0.10, -0.25, -0.25), (0.05, 0.25, 0.0), (5, 20, 5)),
    # Testing box: 0.2 x 0.8 x 0.3 m.
    "large": Box("large", (-0.15, -0.40, -0.30), (0.05, 0.40, 0.0), (8, 22, 10)),
}


def sweep_waypoints(box: Box) -> np.ndarray:
    """(N, 3) tip offsets visited by the sweep, in order; one deformation is recorded at each.

    See the module docstring for the order and the count.
    """
    nx, ny, nz = box.divisions
    xs = np.linspace(box.low[0], box.high[0], nx + 2)
    ys = np.linspace(box.low[1], box.high[1], ny + 2)
    dz = box.size[2] / (nz + 1)
    snake = [(x, y) for line, y in enumerate(ys) for x in (xs if line % 2 == 0 else xs[::-1])]
    xy = (0.0, 0.0)  # the sweep starts at the initial tip
    waypoints = []
    for level in range(1, nz + 2):
        z = box.high[2] - level * dz
        waypoints.append((*xy, z))  # the descent
        # Odd levels run the snake forwards, even levels backwards from where it ended.
        plane = snake if level % 2 == 1 else snake[::-1]
        waypoints += [(x, y, z) for x, y in plane]
        xy = plane[-1]
    return np.asarray(waypoints)


@dataclass
class Database:
    """Recorded deformations.

    Attributes:
        tip: (N, 3) tip positions (m, world frame) at which each deformation was recorded.
        nodes: (N, 200, 3) positions of all mesh nodes (m, world frame).
        name: "small", "large" or the file's stem.
        meta: everything else stored in the file (box, grid, time mode, settle steps, ...).
    """

    tip: np.ndarray
    nodes: np.ndarray
    name: str = ""
    meta: dict | None = None

    def __len__(self) -> int:
        return len(self.tip)

    def goals(self, n_nodes: int) -> np.ndarray:
        """(N, n_nodes, 3) desired positions P_d of the paper's ``n_nodes`` selected nodes."""
        return self.nodes[:, list(selected_nodes(n_nodes))].astype(np.float64)


def database_path(name: str) -> Path:
    return DATABASE_DIR / f"{name}.npz"


def load_database(name_or_path: str | Path) -> Database:
    """Load ``"small"``, ``"large"`` or a path to a ``.npz`` written by :func:`save_database`."""
    path = Path(name_or_path)
    if str(name_or_path) in BOXES:
        path = database_path(str(name_or_path))
    elif path.suffix != ".npz":
        raise ValueError(f"unknown database {name_or_path!r}: use 'small', 'large' or a "
                         ".npz file path")
    if not path.is_file():
        hint = (f"; generate it with `dlo-course database --box {name_or_path}`"
                if str(name_or_path) in BOXES else "")
        raise FileNotFoundError(f"no deformation database at {path}{hint}")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except Exception as err:  # zip and pickle errors have many types
        raise ValueError(f"{path} is not a readable deformation database: {err}") from err
    for key in ("tip", "nodes"):
        if key not in arrays:
            raise ValueError(f"{path} is malformed: it has no '{key}' array "
                             f"(found {sorted(arrays)})")
    tip, nodes = arrays.pop("tip"), arrays.pop("nodes")
    if tip.ndim != 2 or tip.shape[1] != 3 or nodes.shape != (len(tip), 200, 3):
        raise ValueError(f"{path} is malformed: expected tip (N, 3) and nodes (N, 200, 3), "
                         f"got {tip.shape} and {nodes.shape}")
    if not (np.all(np.isfinite(tip)) and np.all(np.isfinite(nodes))):
        raise ValueError(f"{path} is malformed: it holds non-finite positions")
    return Database(tip=tip, nodes=nodes, name=path.stem, meta=arrays)


def save_database(path: Path, tip: np.ndarray, nodes: np.ndarray, **meta) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial.npz")
    np.savez_compressed(tmp, tip=np.asarray(tip, np.float64),
                        nodes=np.asarray(nodes, np.float32), **meta)
    tmp.replace(path)
    return path


# Holding still for 15 actions (45 ms of "code" physics) after each grid step. After a 6 cm
# jerk of the tip, the rod's nodes need about 40 actions to come within 1 cm of rest and 80 to
# come within 1 mm; 15 is what the compute budget of this project allowed (3581 deformations
# at about 0.1 s per action). The residual speed is stored with every deformation.
DEFAULT_SETTLE_STEPS = 15


def move_tip(scene, target: np.ndarray, max_actions: int = 50) -> int:
    """Drive the tip to ``target`` with the environment's own actions; return actions used.

    Each action moves the commanded tip by at most v_max * 0.06 s per axis, exactly as an
    agent's action with components in [-1, 1] would; the last one commands ``target`` itself.
    """
    prm = scene.params
    step = prm.v_max * prm.action_duration
    for used in range(1, max_actions + 1):
        remaining = target - scene.tip_position()
        scene.move_tip_to(scene.tip_target(np.clip(remaining / step, -1.0, 1.0)))
        if np.all(np.abs(remaining) <= step):
            return used
    return max_actions


def generate_database(box: str, out: Path | None = None, settle_steps: int | None = None,
                      time_mode: str = "code", limit: int | None = None,
                      progress: bool = True) -> Path:
    """Run the sweep of ``box`` in the simulator and save the database (see module doc).

    Args:
        box: "small" or "large".
        out: output file, default ``data/databases/<box>.npz``.
        settle_steps: actions spent holding the tip still after each move before recording
            (default 15: 45 ms of physics in "code" time; the recorded mean node speed,
            ``node_speed`` in the file, tells how settled each shape was).
        time_mode: "code" or "paper" (see :class:`~dlo_course.simulation.SimParams`).
        limit: stop after this many deformations (a partial file, for a quick look).
        progress: show a progress bar.
    """
    from tqdm.auto import tqdm

    from dlo_course.simulation import RodScene, SimParams

    if box not in BOXES:
        raise ValueError(f"box must be one of {sorted(BOXES)}, got {box!r}")
    settle_steps = DEFAULT_SETTLE_STEPS if settle_steps is None else settle_steps
    if settle_steps < 0:
        raise ValueError("settle_steps must be >= 0")
    spec = BOXES[box]
    offsets = sweep_waypoints(spec)
    if limit is not None:
        offsets = offsets[:limit]
    path = Path(out) if out is not None else database_path(box)
    scene = RodScene(SimParams(time_mode=time_mode))
    tips, nodes, speeds = [], [], []

    def _save(target: Path, complete: bool) -> Path:
        return save_database(
            target, np.array(tips), np.array(nodes), box=np.array(box),
            box_low=np.array(spec.low), box_high=np.array(spec.high),
            divisions=np.array(spec.divisions), offsets=offsets[:len(tips)],
            initial_tip=scene.initial_tip, node_speed=np.array(speeds),
            time_mode=np.array(time_mode), settle_steps=np.array(settle_steps),
            complete=np.array(complete))

    try:
        origin = scene.initial_tip.copy()
        bar = tqdm(offsets, desc=f"sweeping the {box} box", unit="deformation",
                   disable=not progress)
        for offset in bar:
            target = origin + offset
            move_tip(scene, target)
            for _ in range(settle_steps):
                scene.move_tip_to(target)
            before = scene.node_positions()
            scene.move_tip_to(target)
            after = scene.node_positions()
            if scene.is_unstable(after):
                raise RuntimeError(f"the simulation blew up at tip offset {offset}")
            tips.append(scene.tip_position())
            nodes.append(after)
            # Mean node speed over the last action: how settled the recorded shape is.
            speeds.append(np.mean(np.linalg.norm(after - before, axis=1))
                          / scene.params.physics_time_per_action)
            if len(tips) % 100 == 0 and len(tips) < len(offsets):  # a partial file, for safety
                _save(path.with_suffix(".partial.npz"), False)
    finally:
        scene.close()
    out_path = _save(path, limit is None or limit >= len(sweep_waypoints(spec)))
    path.with_suffix(".partial.npz").unlink(missing_ok=True)
    return out_path
