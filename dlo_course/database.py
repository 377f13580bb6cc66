"""Deformation databases: the goal shapes of the paper (Section V-C, Fig. 3).

The robot sweeps its tip through a box of offsets from the initial tip position, in a
boustrophedon (snake) order, and records the positions of all 200 mesh nodes (and the tip)
along the way. Any node selection (2, 4 or 6 nodes) is then a view of the same file:
``load_database("small").goals(4)`` has shape (N, 4, 3).

Two recording protocols (``meta["protocol"]`` in every file):

* ``"authors_sweep"`` (default, :func:`authors_sweep`): exactly what the authors' generator
  did, verified record by record against their files (FACTS.md, "The authors' sweep, move by
  move"). The tip is moved in small steps, each a single IK target followed by two physics
  steps (6 ms), and the rod is recorded *at once*, while it is still being dragged: every
  goal is a snapshot of a continuous sweep, not a shape at rest. The first level is at the
  initial height. A box with divisions (nx, ny, nz) has r = n + 1 grid lines and steps
  size / r per axis, and records rz (2 ceil(ry / 2) (rx + 1) + 1) shapes: 930 (small), 2651
  (large).
* ``"settled"`` (:func:`settled_waypoints`, ``settle_steps`` > 0): this course's first
  protocol. The tip visits (nx + 2) x (ny + 2) grid points on each of nz + 1 levels, the
  first one step *below* the initial height, moving with the environment's own actions; at
  each point it holds still for ``settle_steps`` actions before the shape is recorded. Same
  counts, other shapes: after 15 settling actions the rod has relaxed, and it leans the
  other way. ``data/databases/small_settled.npz`` is the small box recorded that way.

The paper's Table I was measured on the authors' *test* files, which hold repeated records of
mostly the sweep's first, uncompressed level (FACTS.md). :meth:`Database.test_goals` gives
exactly those goals, from our own recording of the sweep; the goal sources ``"small-test"``
and ``"large-test"`` (:func:`resolve_goals`) select them anywhere a goal set is asked for.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from dlo_course.mesh import selected_nodes
from dlo_course.paths import DATABASE_DIR

AUTHORS_SWEEP = "authors_sweep"
SETTLED = "settled"
TEST_GOALS_PATH = DATABASE_DIR / "authors_test_goals.csv"
"""For each node count and box, the sweep record behind each goal of the authors' test file."""


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

    @property
    def steps(self) -> np.ndarray:
        """(3,) grid step per axis (m): size / (n + 1)."""
        return self.size / (np.asarray(self.divisions) + 1)

    def contains(self, offsets: np.ndarray) -> np.ndarray:
        """(N,) bool: which of the (N, 3) tip offsets lie in the box, borders included."""
        offsets = np.asarray(offsets, dtype=np.float64)
        return np.all((offsets >= self.low) & (offsets <= self.high), axis=-1)

    @property
    def expected_count(self) -> int:
        """Deformations recorded by either protocol (930 small, 2651 large)."""
        rx, ry, rz = (n + 1 for n in self.divisions)
        return rz * (2 * math.ceil(ry / 2) * (rx + 1) + 1)


BOXES = {
    # Training box: 0.15 x 0.5 x 0.25 m.
    "small": Box("small", (-0.10, -0.25, -0.25), (0.05, 0.25, 0.0), (5, 20, 5)),
    # Testing box: 0.2 x 0.8 x 0.3 m.
    "large": Box("large", (-0.15, -0.40, -0.30), (0.05, 0.40, 0.0), (8, 22, 10)),
}


# ---------------------------------------------------------------------- the authors' sweep
@dataclass(frozen=True)
class Sweep:
    """The moves of the authors' sweep of a box, in order.

    Attributes:
        moves: (M, 3) tip displacement of every move (m): each is one grid step along one axis.
        recorded: (M,) bool, whether the shape after that move is recorded. The first moves,
            to the start corner of the box, are not.
    """

    moves: np.ndarray
    recorded: np.ndarray

    @property
    def offsets(self) -> np.ndarray:
        """(N, 3) nominal tip offset of every recorded shape: the sum of the moves so far.
        The real tip lags behind by centimetres: each move starts where the tip *is*, 6 ms
        after the last one was commanded (median 4 cm, at most 7 cm in the small box)."""
        return np.cumsum(self.moves, axis=0)[self.recorded]


def _moves_to(distance: float, step: float) -> int:
    # ceil, but 0.10 / 0.025 computed as 3.9999999999999996 is 4 moves, not 5.
    return math.ceil(distance / step - 1e-9)


def authors_sweep(box: Box) -> Sweep:
    """The authors' sweep of ``box`` (FACTS.md, "The authors' sweep, move by move").

    From the initial tip: ceil(-low_x / step_x) moves of -step_x, then ceil(-low_y / step_y)
    moves of -step_y, none recorded. Then rz levels, each made of ceil(ry / 2) times
    {rx moves of +step_x, 1 move of +step_y, rx moves of -step_x, 1 move of +step_y}, and
    one move of -step_z; every move of a level is recorded, and the sign of the y moves
    flips from one level to the next, so that the levels snake back and forth.
    """
    sx, sy, sz = box.steps
    rx, ry, rz = (n + 1 for n in box.divisions)
    moves: list[tuple[float, float, float]] = []
    recorded: list[bool] = []

    def add(move: tuple[float, float, float], count: int, record: bool) -> None:
        moves.extend([move] * count)
        recorded.extend([record] * count)

    add((-sx, 0.0, 0.0), _moves_to(-box.low[0], sx), False)
    add((0.0, -sy, 0.0), _moves_to(-box.low[1], sy), False)
    direction = 1.0
    for _level in range(rz):
        for _pair in range(math.ceil(ry / 2)):
            add((sx, 0.0, 0.0), rx, True)
            add((0.0, direction * sy, 0.0), 1, True)
            add((-sx, 0.0, 0.0), rx, True)
            add((0.0, direction * sy, 0.0), 1, True)
        add((0.0, 0.0, -sz), 1, True)
        direction = -direction
    return Sweep(np.asarray(moves, dtype=np.float64), np.asarray(recorded, dtype=bool))


def sweep_levels(box: Box) -> np.ndarray:
    """(N,) level of every record of the authors' sweep (0 = the initial height).

    The z move that ends a level belongs to that level: it is the record its level's
    snake ends with."""
    per_level = box.expected_count // (box.divisions[2] + 1)
    return np.arange(box.expected_count) // per_level


# ---------------------------------------------------------------------- the settled protocol
def settled_waypoints(box: Box) -> np.ndarray:
    """(N, 3) tip offsets of the settled protocol, in order; one shape is recorded at each.

    Each of the nz + 1 levels, from one step below the start down to the bottom of the box,
    is reached by a descent (recorded) and then swept over (nx + 2) x (ny + 2) grid points
    from wall to wall in snake order, each recorded.
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


# ---------------------------------------------------------------------- files
@dataclass
class Database:
    """Recorded deformations.

    Attributes:
        tip: (N, 3) tip positions (m, world frame) at which each deformation was recorded.
        nodes: (N, 200, 3) positions of all mesh nodes (m, world frame).
        name: "small", "large" or the file's stem.
        meta: everything else stored in the file (box, protocol, offsets, node speeds, ...).
    """

    tip: np.ndarray
    nodes: np.ndarray
    name: str = ""
    meta: dict | None = None

    def __len__(self) -> int:
        return len(self.tip)

    @property
    def protocol(self) -> str:
        """"authors_sweep" or "settled" (files written before protocols had names were
        all settled)."""
        return str((self.meta or {}).get("protocol", SETTLED))

    @property
    def box(self) -> str:
        """Name of the box that was swept ("small" or "large"), or "" if unknown."""
        return str((self.meta or {}).get("box", ""))

    def goals(self, n_nodes: int) -> np.ndarray:
        """(N, n_nodes, 3) desired positions P_d of the paper's ``n_nodes`` selected nodes."""
        return self.nodes[:, list(selected_nodes(n_nodes))].astype(np.float64)

    def test_indices(self, n_nodes: int) -> np.ndarray:
        """(T,) record indices of the authors' test goals for ``n_nodes`` on this box, in the
        order of their test file, repeats included (930 for the small box, 2651 for the
        large). Only a complete recording of the authors' sweep has them."""
        selected_nodes(n_nodes)  # validates n_nodes
        if self.protocol != AUTHORS_SWEEP or self.box not in BOXES:
            raise ValueError(f"database {self.name!r} was recorded with the {self.protocol!r} "
                             "protocol; the paper's test goals index the authors' sweep "
                             "(regenerate with `dlo-course database --box small|large`)")
        if len(self) != BOXES[self.box].expected_count:
            raise ValueError(f"database {self.name!r} holds {len(self)} records, not the "
                             f"{BOXES[self.box].expected_count} of the complete {self.box} sweep")
        return _authors_test_records()[(n_nodes, self.box)].copy()

    def test_goals(self, n_nodes: int) -> np.ndarray:
        """(T, n_nodes, 3) the goals Table I was measured on (see :meth:`test_indices`)."""
        return self.goals(n_nodes)[self.test_indices(n_nodes)]

    def held_out_indices(self, n_nodes: int, size: int, seed: int,
                         like_test: bool = True) -> np.ndarray:
        """(size,) record indices that are not the paper's test goals, drawn with repeats
        from ``seed``: goals to choose an agent on without looking at the test.

        With ``like_test``, the draw has the test's mix of sweep levels: the test goals come
        mostly from the sweep's first, least compressed level (FACTS.md; 4 nodes: 735, 158 and
        37 of its 930 draws from levels 0, 1 and 2), while the records left over lie mostly
        on the compressed levels below, so a uniform draw among them measures another task,
        and did not rank agents as the test does (benchmarks/validation_vs_test.py). Each
        draw takes a level with the test's frequency, then a held-out record of that level.
        Without, the draw is uniform over every held-out record."""
        test = self.test_indices(n_nodes)
        held_out = np.setdiff1d(np.arange(len(self)), test)
        rng = np.random.default_rng(seed)
        if not like_test:
            return rng.choice(held_out, size=size)
        levels = sweep_levels(BOXES[self.box])
        share = np.bincount(levels[test], minlength=levels.max() + 1) / len(test)
        drawn_levels = rng.choice(len(share), size=size, p=share)
        by_level = {level: held_out[levels[held_out] == level] for level in np.unique(drawn_levels)}
        if any(len(records) == 0 for records in by_level.values()):
            raise ValueError(f"a sweep level of the test has no held-out record ({n_nodes} "
                             f"nodes, {self.box} box)")
        return np.array([rng.choice(by_level[level]) for level in drawn_levels])


@lru_cache(maxsize=1)
def _authors_test_records() -> dict[tuple[int, str], np.ndarray]:
    if not TEST_GOALS_PATH.is_file():
        raise FileNotFoundError(f"missing {TEST_GOALS_PATH}, the list of the paper's test goals")
    rows: dict[tuple[int, str], list[tuple[int, int]]] = {}
    with TEST_GOALS_PATH.open(newline="") as f:
        for row in csv.DictReader(f):
            key = (int(row["nodes"]), row["database"])
            rows.setdefault(key, []).append((int(row["test_episode_goal"]),
                                             int(row["sweep_record"])))
    return {key: np.array([record for _, record in sorted(pairs)], dtype=np.int64)
            for key, pairs in rows.items()}


def database_path(name: str) -> Path:
    return DATABASE_DIR / f"{name}.npz"


def shipped_databases() -> list[str]:
    """Names of the databases in ``data/databases`` (e.g. "large", "small", "small_settled")."""
    return sorted(p.stem for p in DATABASE_DIR.glob("*.npz") if not p.stem.startswith("."))


class DatabaseError(ValueError):
    """A deformation database or goal file that cannot be read (truncated, corrupt) or does
    not hold what it should."""


def load_database(name_or_path: str | Path) -> Database:
    """Load a shipped database by name ("small", "large", "small_settled") or a path to a
    ``.npz`` written by :func:`save_database`."""
    path = Path(name_or_path)
    if path.suffix != ".npz":
        name = str(name_or_path)
        if name not in BOXES and not database_path(name).is_file():
            raise ValueError(f"unknown database {name!r}: use one of "
                             f"{sorted(set(BOXES) | set(shipped_databases()))} or a .npz path")
        path = database_path(name)
    if not path.is_file():
        hint = (f"; generate it with `dlo-course database --box {name_or_path}`"
                if str(name_or_path) in BOXES else "")
        raise FileNotFoundError(f"no deformation database at {path}{hint}")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except Exception as err:  # zip and pickle errors have many types
        raise DatabaseError(f"{path} is not a readable deformation database (truncated or "
                            f"corrupt?): {err}") from err
    for key in ("tip", "nodes"):
        if key not in arrays:
            raise DatabaseError(f"{path} is malformed: it has no '{key}' array "
                                f"(found {sorted(arrays)})")
    tip, nodes = arrays.pop("tip"), arrays.pop("nodes")
    if tip.ndim != 2 or tip.shape[1] != 3 or nodes.shape != (len(tip), 200, 3):
        raise DatabaseError(f"{path} is malformed: expected tip (N, 3) and nodes "
                            f"(N, 200, 3), got {tip.shape} and {nodes.shape}")
    if not (np.all(np.isfinite(tip)) and np.all(np.isfinite(nodes))):
        raise DatabaseError(f"{path} is malformed: it holds non-finite positions")
    return Database(tip=tip, nodes=nodes, name=path.stem, meta=arrays)


def save_database(path: Path, tip: np.ndarray, nodes: np.ndarray, **meta) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial.npz")
    np.savez_compressed(tmp, tip=np.asarray(tip, np.float64),
                        nodes=np.asarray(nodes, np.float32), **meta)
    tmp.replace(path)
    return path


# ---------------------------------------------------------------------- goal sources
GOAL_SOURCES = ("small", "large", "small-test", "large-test")
"""Named goal sets: a whole database, or the paper's test goals drawn from it."""


def goal_array(goals: np.ndarray, n_nodes: int) -> np.ndarray:
    """Check and return desired positions as a float64 array (K, n_nodes, 3).

    A single goal of shape (n_nodes, 3) becomes (1, n_nodes, 3); anything else of the wrong
    shape, empty, or non-finite raises ``ValueError``.
    """
    array = np.asarray(goals, dtype=np.float64)
    if array.ndim == 2 and array.shape == (n_nodes, 3):
        array = array[None]  # a single goal
    if array.ndim != 3 or array.shape[1:] != (n_nodes, 3) or len(array) == 0:
        raise ValueError(f"goals must have shape (K, {n_nodes}, 3) for n_nodes={n_nodes}, "
                         f"got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError("goals must be finite")
    return array


def resolve_goals(source: str | Path | np.ndarray, n_nodes: int) -> np.ndarray:
    """The one place where a goal source becomes goal shapes (K, n_nodes, 3), float64.

    ``source`` is one of:

    * a database name: ``"small"``, ``"large"`` (every record of the sweep) or another
      shipped database (``"small_settled"``);
    * ``"small-test"`` or ``"large-test"``: the paper's test goals (:meth:`Database.test_goals`);
    * a path: a database ``.npz``, a ``.npy`` array (K, n_nodes, 3), or a ``.npz`` holding
      such an array as ``goals``;
    * an array (K, n_nodes, 3), or a single goal (n_nodes, 3).
    """
    if isinstance(source, np.ndarray):
        return goal_array(source, n_nodes)
    text = str(source)
    if text.endswith("-test") and text[:-len("-test")] in BOXES:
        return load_database(text[:-len("-test")]).test_goals(n_nodes)
    path = Path(source)
    if path.suffix == ".npy":
        if not path.is_file():
            raise FileNotFoundError(f"no goal file at {path}")
        try:
            array = np.load(path, allow_pickle=False)
        except Exception as err:  # truncated or not an array file
            raise DatabaseError(f"{path} is not a readable goal array: {err}") from err
        return goal_array(array, n_nodes)
    if path.suffix == ".npz" and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as data:
                goals = (data["goals"] if "goals" in data.files and "nodes" not in data.files
                         else None)
        except Exception as err:  # a truncated zip raises one of many kinds
            raise DatabaseError(f"{path} is not a readable goal file: {err}") from err
        if goals is not None:
            return goal_array(goals, n_nodes)
    return load_database(source).goals(n_nodes)


# ---------------------------------------------------------------------- recording
# The settled protocol holds the tip still for 15 actions (45 ms of "code" physics) after each
# grid step. After a 6 cm jerk of the tip, the rod's nodes need about 40 actions to come
# within 1 cm of rest; 15 is what the first round's compute budget allowed.
DEFAULT_SETTLE_STEPS = 15

# The authors' protocol, in physics steps (``stepSimulation()`` calls of 3 ms):
SWEEP_STEPS_BEFORE = 3
"""Their world had been stepped 3 times after anchoring (construction, first reset)."""
SWEEP_STEPS_PER_START_MOVE = 1
"""A move to the start corner: one step, nothing recorded."""
SWEEP_STEPS_PER_MOVE = 2
"""A recorded move: two steps (one hidden in the drawing of the gripper's cross), then the
record. With one step instead of two, the first level is 4.5 cm off their file."""


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


def _record_authors_sweep(scene, box: Box, limit: int | None, record) -> None:
    """Run the authors' sweep in ``scene``, calling ``record(nodes, seconds)`` after every
    recorded move with the nodes as they were ``seconds`` of physics before (the caller
    reads the scene's present state)."""
    sweep = authors_sweep(box)
    scene.step_physics(SWEEP_STEPS_BEFORE)
    recorded = 0
    for move, is_recorded in zip(sweep.moves, sweep.recorded):
        # Each target starts from where the tip *is* (as the last step left it), not where it
        # was sent, and is clipped to the tip workspace, whose top is the initial height: the
        # authors' tip drifts a little from the grid, and so do the goals, but never upwards.
        scene.command_tip_plain_ik(scene.clip_to_workspace(scene.tip_position() + move))
        if not is_recorded:
            scene.step_physics(SWEEP_STEPS_PER_START_MOVE)
            continue
        scene.step_physics(SWEEP_STEPS_PER_MOVE - 1)
        before = scene.node_positions()
        scene.step_physics(1)
        record(before, scene.params.time_step)
        recorded += 1
        if limit is not None and recorded >= limit:
            return


def _record_settled(scene, box: Box, settle_steps: int, limit: int | None, record) -> None:
    """The settled protocol: move with actions, hold ``settle_steps`` actions, record (the
    ``record`` callback as in :func:`_record_authors_sweep`)."""
    offsets = settled_waypoints(box)[:limit]
    for offset in offsets:
        target = scene.initial_tip + offset
        move_tip(scene, target)
        for _ in range(settle_steps):
            scene.move_tip_to(target)
        before = scene.node_positions()
        scene.move_tip_to(target)
        record(before, scene.params.physics_time_per_action)


def generate_database(box: str, out: Path | None = None, settle_steps: int | None = None,
                      time_mode: str = "code", limit: int | None = None,
                      progress: bool = True, params=None) -> Path:
    """Record the database of ``box`` in the simulator and save it (see the module doc).

    Args:
        box: "small" or "large".
        out: output file, default ``data/databases/<box>.npz``.
        settle_steps: None (default) for the authors' sweep; a number of actions for the
            settled protocol (the first round's database used 15).
        time_mode: "code" or "paper"; only the settled protocol's actions depend on it (the
            authors' sweep is defined in physics steps).
        limit: stop after this many deformations (a partial file, for a quick look).
        progress: show a progress bar.
        params: the scene's :class:`~dlo_course.simulation.SimParams` (default: the
            paper's), e.g. to record a database of a rod of another material.

    Every file stores ``protocol`` and its parameters, the nominal tip ``offsets``, the
    ``initial_tip``, and ``node_speed``: the mean node speed over the last physics step (authors'
    sweep) or action (settled) before the record, which tells how far the shape was from rest.
    """
    from tqdm.auto import tqdm

    from dlo_course.simulation import RodScene, SimParams

    if box not in BOXES:
        raise ValueError(f"box must be one of {sorted(BOXES)}, got {box!r}")
    if settle_steps is not None and settle_steps < 0:
        raise ValueError("settle_steps must be >= 0")
    if limit is not None and limit < 1:
        raise ValueError("limit must be >= 1")
    spec = BOXES[box]
    if settle_steps is None:
        protocol, offsets = AUTHORS_SWEEP, authors_sweep(spec).offsets
        protocol_meta: dict = dict(steps_before=SWEEP_STEPS_BEFORE,
                                   steps_per_start_move=SWEEP_STEPS_PER_START_MOVE,
                                   steps_per_move=SWEEP_STEPS_PER_MOVE, ik=np.array("plain"))
    else:
        protocol, offsets = SETTLED, settled_waypoints(spec)
        protocol_meta = dict(settle_steps=settle_steps, time_mode=np.array(time_mode))
    total = len(offsets) if limit is None else min(limit, len(offsets))
    path = Path(out) if out is not None else database_path(box)
    partial = path.with_suffix(".partial.npz")
    scene = RodScene((params or SimParams()).with_(time_mode=time_mode))
    tips, nodes, speeds = [], [], []
    bar = tqdm(total=total, desc=f"{protocol}: {box} box", unit="deformation",
               disable=not progress)

    def save(target: Path) -> Path:
        return save_database(
            target, np.array(tips), np.array(nodes), box=np.array(box),
            box_low=np.array(spec.low), box_high=np.array(spec.high),
            divisions=np.array(spec.divisions), offsets=offsets[:len(tips)],
            initial_tip=scene.initial_tip, node_speed=np.array(speeds),
            protocol=np.array(protocol), complete=np.array(len(tips) == len(offsets)),
            **protocol_meta)

    def record(before: np.ndarray, seconds: float) -> None:
        after = scene.node_positions()
        if scene.is_unstable(after):
            raise RuntimeError(f"the simulation blew up at record {len(tips)} of the {box} box")
        tips.append(scene.tip_position())
        nodes.append(after)
        speeds.append(np.mean(np.linalg.norm(after - before, axis=1)) / seconds)
        bar.update(1)
        if len(tips) % 100 == 0 and len(tips) < total:  # a partial file, for a quick look
            save(partial)

    try:
        if protocol == AUTHORS_SWEEP:
            _record_authors_sweep(scene, spec, limit, record)
        else:
            _record_settled(scene, spec, settle_steps, limit, record)
        out_path = save(path)
    finally:
        bar.close()
        scene.close()
    partial.unlink(missing_ok=True)
    return out_path
