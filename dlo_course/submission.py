"""A student's own agent, handed in and checked: the graded protocol, the report, its check.

Lesson 13 ends by handing in the 2-node agent the student trained in lesson 9: a folder
:data:`SUBMISSION_DIR` beside the notebook, holding the actor file (:data:`ACTOR_NAME`) and a
JSON report (:data:`REPORT_NAME`) of what :func:`evaluate_graded` measured on a small, fixed
protocol (:data:`GRADED_PROTOCOL`: four of the paper's small-database test goals, one after
the other on one rod, at most 6 actions each, 0.05 m). The grader
(``tests/grading/test_13_capstone_table_one.py``) evaluates the handed-in actor again on the
same protocol and gives the points only if the report says what the actor does
(:func:`report_problems`); the class CSV collects the reports' claims
(:func:`csv_fields`).

The report, a JSON object:

======================= ================================================================
``format``              :data:`REPORT_FORMAT`
``protocol``            :data:`GRADED_PROTOCOL`, as it was run
``n_nodes``             nodes of the actor's observation (2 for lesson 9's agent)
``actor_sha256``        SHA-256 of the actor file's bytes (hex)
``goals``               one entry per graded goal, in protocol order: ``goal_index``
                        (in the small database's test goals), ``done`` (the mean node
                        distance went below the threshold), ``final_distance`` (m, when
                        the episode stopped), ``steps`` (actions taken)
``done_percent``        100 x done goals / goals
``run``                 the training run's record from its files (:func:`run_summary`),
                        or ``null`` when the actor came without its run directory
======================= ================================================================

The protocol builds and settles the world once (the costly part: about 3 s of CPU) and runs
its episodes one after the other, each from the shape the previous one ended in, without the
settling of a reset: about 9 s of CPU in all for an actor that reaches no goal. It forks
nothing (the grader's sandbox forbids it) and is deterministic, so the same actor gives the
same numbers on any run of the same code, up to the last bits of floating point (hence
:data:`DISTANCE_TOLERANCE`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np

REPORT_FORMAT = 1
SUBMISSION_DIR = "13_submission"
"""The handed-in folder's name, beside the notebook (``Path.cwd()`` of a running notebook)."""
REPORT_NAME = "report.json"
ACTOR_NAME = "actor.pt"

GRADED_PROTOCOL: dict[str, Any] = {
    "goals": "small-test",
    "goal_indices": [0, 10, 32, 40],
    "max_steps": 6,
    "threshold": 0.05,
}
"""The graded protocol: goals ``goal_indices`` of the paper's small-database test goals
(:func:`dlo_course.database.resolve_goals` of ``goals``), one episode each, in this order on
one rod (built once, each episode starting where the last one stopped), at most
``max_steps`` actions, done below ``threshold`` m of mean node distance. Small on purpose:
the grader runs it again for every student."""

MAX_ACTOR_BYTES = 32 * 2**20
"""The largest actor file a hand-in may hold (lesson 9's actor is about 0.6 MB)."""

DISTANCE_TOLERANCE = 1e-3
"""m: how far a reported final distance may be from the grader's."""


def sha256_of(path: str | Path) -> str:
    """The hex SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def actor_file(agent: str | Path) -> Path:
    """The actor file of an agent: ``agent/actor.pt`` for a folder (a run directory or a
    shipped agent), else ``agent`` itself."""
    path = Path(agent)
    return path / ACTOR_NAME if path.is_dir() else path


# ------------------------------------------------------------------ what the points reward

LESSON_N_NODES = 2
"""The node count of lesson 9's agent: a hand-in of another node count is not that agent."""

LESSON_EPISODES = 100
"""Episodes of lesson 9's training (one agent, at most 60 actions each, ending at the goal):
at most 6 000 transitions, 1% of the paper's 604 800."""


def lesson_run_config(out_dir: str | Path, episodes: int = LESSON_EPISODES, fast: bool = False):
    """The :class:`~dlo_course.config.TrainConfig` of lesson 9's own agent, which lesson 13
    hands in: the ``recipe`` preset on 2 nodes (its 0.03 m training threshold), one agent in
    the notebook's process, trained by the student's ``play_episode``
    (:func:`dlo_course.trainer.train` with ``play_episode=``), so its episodes end at the
    goal; no validation (the last actor is kept); the resume state every 5 episodes. ``fast``:
    the course's fast mode, the same mechanics at smoke scale (episodes of 4 steps, batches
    of 4, the resume state after every episode)."""
    import dataclasses

    from dlo_course.config import PRESETS, preset

    config = preset("recipe", env_kwargs={**PRESETS["recipe"].env_kwargs,
                                          "n_nodes": LESSON_N_NODES},
                    episodes=episodes, stop_at_goal=True, validate_every=0,
                    checkpoint_every=1 if fast else 5, out_dir=str(out_dir),
                    expected_agents=None)
    if fast:
        config = dataclasses.replace(config, steps_per_episode=4,
                                     ddpg=dataclasses.replace(config.ddpg, batch_size=4))
    return config


PROBE_COUNT, PROBE_SEED = 256, 0
"""How many observations :func:`probe_observations` draws, and from which seed."""

LIKENESS_TOLERANCE = 0.1
"""Mean absolute difference of actions (in [-1, 1] per component) on
:func:`probe_observations` below which a handed-in actor *behaves like* a shipped one
(:func:`shipped_likeness`). Changing one weight of a shipped actor by 1e-6 or scaling them
all by 1.0001 moves its actions by at most 1e-4; Gaussian noise of 0.1, 0.2, 0.3, 0.5 x each
weight tensor's spread by 0.05, 0.10, 0.15, 0.27; agents trained apart differ by 0.23-0.31
(the shipped 6-node seeds). So 0.1, under half the closest pair trained apart: a shipped actor
fine-tuned, or disturbed on purpose, until its actions move by 0.1 on average counts as the
student's, the grey zone where behaviour alone cannot tell
(``benchmarks/own_agent_floor.py``, ``benchmarks/results/own_agent_floor/``)."""

FLOOR_SHARE = 0.75
"""The learning floor: on the graded protocol the actor's mean final distance must be at most
this share of the mean distance that doing nothing leaves (the distance of each goal from the
shape the protocol starts in), i.e. the actor must close at least a quarter of the gap on
average. Every graded goal is 13-18 cm from that shape, so doing nothing reaches none of them;
an untrained actor's outputs are close to zero (the last layer starts small) and it ends where
doing nothing does (``benchmarks/own_agent_floor.py``)."""


def probe_observations(n_nodes: int, count: int = PROBE_COUNT, seed: int = PROBE_SEED
                       ) -> np.ndarray:
    """(count, 6 + 6 n_nodes) float32 observations of the rod as it can be: the tip and the
    nodes of one record of the small database (at rest: zero tip velocity) and, as the goal,
    the nodes of another, both drawn from ``seed``. Where actors are compared."""
    return _probe_observations(int(n_nodes), int(count), int(seed)).copy()


@functools.lru_cache(maxsize=4)
def _probe_observations(n_nodes: int, count: int, seed: int) -> np.ndarray:
    from dlo_course.database import load_database

    database = load_database("small")
    shapes = database.goals(n_nodes).reshape(len(database), -1)
    rng = np.random.default_rng(seed)
    now, goal = rng.integers(len(database), size=(2, count))
    return np.concatenate([database.tip[now], np.zeros((count, 3)), shapes[now], shapes[goal]],
                          axis=1).astype(np.float32)


def probe_actions(actor, n_nodes: int) -> np.ndarray:
    """(PROBE_COUNT, 3) the deterministic actor's actions on :func:`probe_observations`."""
    from dlo_course.ddpg import policy_action

    return policy_action(actor, probe_observations(n_nodes))


def shipped_actor_files() -> list[Path]:
    """Every actor the course ships: each ``actor.pt`` below ``data/checkpoints/`` (the
    agents of every node count and the seeds' agents)."""
    from dlo_course.paths import AGENTS_DIR

    return sorted(AGENTS_DIR.rglob(ACTOR_NAME))


def shipped_likeness(actions: np.ndarray, n_nodes: int) -> list[tuple[str, float]]:
    """How far a handed-in actor's :func:`probe_actions` are from each shipped actor's of the
    same node count (others take other observations: :data:`LESSON_N_NODES` refuses them):
    ``[(path relative to the data folder, mean absolute action difference), ...]``, nearest
    first."""
    from dlo_course.paths import DATA_DIR

    actions = np.asarray(actions, dtype=np.float64)
    found = []
    for path in shipped_actor_files():
        info = path.stat()
        nodes, theirs = _shipped_behaviour(str(path), info.st_size, info.st_mtime_ns)
        if nodes != n_nodes:
            continue
        distance = float(np.mean(np.abs(actions - theirs))) if actions.shape == theirs.shape \
            else math.inf
        found.append((path.relative_to(DATA_DIR).as_posix(), distance))
    return sorted(found, key=lambda item: item[1])


@functools.lru_cache(maxsize=32)
def _shipped_behaviour(path: str, size: int, mtime_ns: int) -> tuple[int, np.ndarray]:
    """(n_nodes, probe actions as float64) of a shipped actor file, once per version of it
    (``size`` and ``mtime_ns`` name the version)."""
    behaviour = actor_behaviour(path)
    return behaviour["n_nodes"], behaviour["probe_actions"].astype(np.float64)


def actor_behaviour(agent: str | Path) -> dict[str, Any]:
    """``{"n_nodes": int, "probe_actions": (PROBE_COUNT, 3) array}``: a trained agent's node
    count and its actions on :func:`probe_observations` (no simulation: well under a second),
    for :func:`likeness_problems`."""
    from dlo_course.evaluation import load_actor

    actor, n_nodes = load_actor(actor_file(agent))
    return {"n_nodes": int(n_nodes), "probe_actions": probe_actions(actor, n_nodes)}


def likeness_problems(behaviour: dict[str, Any]) -> list[str]:
    """Why a handed-in actor (:func:`actor_behaviour`, run by the grader) is not lesson 9's
    agent of the student's own, whatever its bytes (an empty list: it may be): another node
    count (:data:`LESSON_N_NODES`), or actions within :data:`LIKENESS_TOLERANCE` of a shipped
    actor's."""
    n_nodes = int(behaviour["n_nodes"])
    if n_nodes != LESSON_N_NODES:
        return [f"the actor takes {n_nodes}-node observations: lesson 9 trains a "
                f"{LESSON_N_NODES}-node agent, hand in that one"]
    near = [(path, d) for path, d in shipped_likeness(behaviour["probe_actions"], n_nodes)
            if d < LIKENESS_TOLERANCE]
    if not near:
        return []
    path, distance = near[0]
    return [f"the actor behaves like the shipped {path} (its actions differ by {distance:.2g} "
            f"on average on the grader's test observations, less than {LIKENESS_TOLERANCE:g}): "
            "it is not an agent you trained; hand in lesson 9's"]


def floor_problems(measured: dict[str, Any]) -> list[str]:
    """Why the grader's own evaluation of a handed-in actor (:func:`evaluate_graded`) is below
    the learning floor (:data:`FLOOR_SHARE`; an empty list: above it)."""
    final = float(np.mean([g["final_distance"] for g in measured["goals"]]))
    nothing = float(np.mean(measured["do_nothing_distances"]))
    if final <= FLOOR_SHARE * nothing:
        return []
    return [f"the actor learned too little: it ends {final:.3f} m from the graded goals on "
            f"average, where doing nothing leaves {nothing:.3f} m; an agent must end within "
            f"{FLOOR_SHARE:g} x that ({FLOOR_SHARE * nothing:.3f} m). Train it longer (lesson 9, "
            "section 7) and hand it in again"]


def evaluate_graded(agent: str | Path, protocol: dict[str, Any] | None = None
                    ) -> dict[str, Any]:
    """Run the graded protocol on a trained agent (:func:`dlo_course.evaluation.load_actor`).

    Returns:
        ``{"n_nodes": int, "goals": [{"goal_index", "done", "final_distance", "steps"}, ...],
        "done_percent": float, "do_nothing_distances": [float, ...]}``, the goals in
        protocol order. ``do_nothing_distances`` (m): each goal's mean node distance from
        the shape the protocol starts in, where a policy that does nothing leaves the rod
        (:func:`floor_problems`).
    """
    from dlo_course.database import resolve_goals
    from dlo_course.env import make_env, mean_node_distance
    from dlo_course.evaluation import EpisodeTrace, _play, load_actor

    protocol = dict(GRADED_PROTOCOL if protocol is None else protocol)
    actor, n_nodes = load_actor(actor_file(agent))
    indices = [int(i) for i in protocol["goal_indices"]]
    threshold = float(protocol["threshold"])
    goal_shapes = resolve_goals(protocol["goals"], n_nodes)[indices]
    env = make_env(max_episode_steps=None, n_nodes=n_nodes, goals=goal_shapes,
                   threshold=threshold, time_mode="code")
    goals = []
    try:
        # One world, built and settled once (the costly part); every later episode starts
        # where the previous one stopped, from its new goal at once.
        obs, info = env.reset(options={"reinitialize": True, "goal_index": 0})
        start = env.unwrapped.scene.node_positions()[env.unwrapped.node_ids]
        do_nothing = [mean_node_distance(start, goal) for goal in goal_shapes]
        for k, index in enumerate(indices):
            if k:
                obs, info = env.unwrapped.set_goal(k)
            _, distances, _ = _play(actor, env, obs, int(protocol["max_steps"]))
            record = EpisodeTrace(float(info["distance"]), tuple(distances)).record(
                k, index, threshold)
            goals.append({"goal_index": index, "done": bool(record.done),
                          "final_distance": float(record.final_distance),
                          "steps": int(record.steps)})
    finally:
        env.close()
    done = sum(g["done"] for g in goals)
    return {"n_nodes": int(n_nodes), "goals": goals,
            "done_percent": 100.0 * done / len(goals),
            "do_nothing_distances": [float(d) for d in do_nothing]}


def run_summary(run_dir: str | Path) -> dict[str, Any] | None:
    """What the training run behind an agent cost, from its files: ``episodes`` (per agent),
    ``transitions`` (all agents), ``wall_time_s`` (s of training), ``ranks`` and ``config``
    (the run's ``config.json``); None if the folder holds no ``progress.csv``."""
    from dlo_course.rundir import CONFIG_FILE, read_json, run_record

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        return None
    record = run_record(run_dir)
    if "transitions" not in record:
        return None
    config = read_json(run_dir / CONFIG_FILE) if (run_dir / CONFIG_FILE).is_file() else None
    return {"episodes": int(record["episodes_per_agent"]),
            "transitions": int(record["transitions"]),
            "wall_time_s": float(record["wall_time_h"]) * 3600,
            "ranks": record.get("ranks"), "config": config}


def write_submission(agent: str | Path, folder: str | Path) -> dict[str, Any]:
    """Hand in an agent: copy its actor file into ``folder`` (created) as
    :data:`ACTOR_NAME`, evaluate it on :data:`GRADED_PROTOCOL` and write the report
    (:data:`REPORT_NAME`; the module docstring gives its fields).

    Args:
        agent: a run directory (its record is reported), a trained agent's folder or an
            actor file.

    Returns:
        The report, as written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    source = actor_file(agent)
    actor = folder / ACTOR_NAME
    if source.resolve() != actor.resolve():
        shutil.copyfile(source, actor)
    measured = evaluate_graded(actor)
    report = {"format": REPORT_FORMAT, "protocol": dict(GRADED_PROTOCOL),
              "n_nodes": measured["n_nodes"], "actor_sha256": sha256_of(actor),
              "goals": measured["goals"], "done_percent": measured["done_percent"],
              "run": run_summary(agent) if Path(agent).is_dir() else None}
    (folder / REPORT_NAME).write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    return report


class SubmissionError(ValueError):
    """A handed-in folder that cannot be graded (missing, unreadable, too large, a link)."""


MAX_REPORT_BYTES = 256 * 2**10
"""The largest report a hand-in may hold (lesson 13 writes about 3 kB)."""
MAX_REPORT_NESTING = 16
"""The deepest nesting of lists and objects a report may have (lesson 13 writes 4 levels)."""


def _read_limited(path: Path, limit: int, how: str) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, its last component never
    followed if it is a link (``O_NOFOLLOW``) and never opened if it is not a regular file
    (a FIFO would block). Raises SubmissionError with what is wrong and ``how`` to fix it."""
    import os
    import stat

    try:
        info = path.lstat()
    except OSError:
        raise SubmissionError(f"no {path.name} in {path.parent}: {how}") from None
    if stat.S_ISLNK(info.st_mode):
        # Nothing of the target is read or told: a link could point anywhere on the grader's
        # machine.
        raise SubmissionError(f"{path.name} is a symbolic link; hand in the file itself: {how}")
    if not stat.S_ISREG(info.st_mode):
        raise SubmissionError(f"{path.name} is not a regular file: {how}")
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_NONBLOCK", 0))
    except OSError as err:
        raise SubmissionError(f"{path.name} cannot be opened ({err.strerror}): {how}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped since lstat
            raise SubmissionError(f"{path.name} is not a regular file: {how}")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1)
    finally:
        os.close(fd)
    if len(data) > limit:
        raise SubmissionError(f"{path.name} is larger than {limit / 2**20:.2g} MB, not what "
                              f"lesson 13 writes: {how}")
    return data


def _nesting(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in JSON text, strings skipped; counted without
    recursion, so that deep text cannot exhaust the parser's stack."""
    depth = deepest = 0
    in_string = escaped = False
    for char in text:
        if in_string:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif char in "]}":
            depth -= 1
    return deepest


def _no_constant(name: str):
    raise ValueError(f"{name} is not a number")


def parse_report(data: bytes) -> dict[str, Any]:
    """A report's JSON object from its bytes: UTF-8, at most :data:`MAX_REPORT_NESTING`
    levels deep, no NaN or infinity. Raises ValueError with what is wrong."""
    text = data.decode("utf-8")
    if _nesting(text) > MAX_REPORT_NESTING:
        raise ValueError(f"nested more than {MAX_REPORT_NESTING} levels deep")
    report = json.loads(text, parse_constant=_no_constant)
    if not isinstance(report, dict):
        raise ValueError(f"it holds a {type(report).__name__}, not a report object")
    return report


def read_submission(folder: str | Path) -> tuple[dict[str, Any], bytes]:
    """The report and the actor file's bytes of a handed-in folder, read with limits: no
    symbolic link followed (the folder or its files), at most :data:`MAX_REPORT_BYTES` and
    :data:`MAX_ACTOR_BYTES`, the report's nesting bounded (:func:`parse_report`).

    Raises:
        SubmissionError: with what is wrong and how to hand in again.
    """
    folder = Path(folder)
    how = ("run the last cell of lesson 13 (section 11), which writes both, and hand in the "
           f"folder {SUBMISSION_DIR}/ beside the notebook")
    if folder.is_symlink():
        raise SubmissionError(f"{folder.name} is a symbolic link; hand in the folder itself: "
                              f"{how}")
    missing = [name for name in (REPORT_NAME, ACTOR_NAME)
               if not (folder / name).is_symlink() and not (folder / name).exists()]
    if missing:
        raise SubmissionError(f"no {' and no '.join(missing)} in {folder}: {how}")
    actor = _read_limited(folder / ACTOR_NAME, MAX_ACTOR_BYTES, how)
    data = _read_limited(folder / REPORT_NAME, MAX_REPORT_BYTES, how)
    try:
        report = parse_report(data)
    except (ValueError, RecursionError) as err:  # UnicodeDecodeError is a ValueError
        raise SubmissionError(f"{REPORT_NAME} is not a readable report ({str(err)[:200]}): "
                              f"{how}") from None
    return report, actor


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


def report_type_problems(report: dict[str, Any]) -> list[str]:
    """What in a report is missing or of the wrong type (an empty list: nothing)."""
    problems = []
    if report.get("format") != REPORT_FORMAT:
        problems.append(f"format {str(report.get('format'))[:20]!r} is not {REPORT_FORMAT}")
    if not _is_int(report.get("n_nodes")):
        problems.append("n_nodes is not an integer")
    if not isinstance(report.get("actor_sha256"), str):
        problems.append("actor_sha256 is not a string")
    if not _is_number(report.get("done_percent")):
        problems.append("done_percent is not a number")
    goals = report.get("goals")
    if not isinstance(goals, list) or len(goals) != len(GRADED_PROTOCOL["goal_indices"]):
        problems.append(f"goals is not a list of {len(GRADED_PROTOCOL['goal_indices'])} "
                        "results")
    else:
        for k, (goal, index) in enumerate(zip(goals, GRADED_PROTOCOL["goal_indices"])):
            if not (isinstance(goal, dict) and goal.get("goal_index") == index
                    and _is_int(goal["goal_index"]) and isinstance(goal.get("done"), bool)
                    and _is_number(goal.get("final_distance"))
                    and goal["final_distance"] >= 0 and _is_int(goal.get("steps"))):
                problems.append(f"goals[{k}] is not a result of goal {index} (goal_index, "
                                "done: true or false, final_distance: a number of m, steps)")
    run = report.get("run")
    if run is not None and not (isinstance(run, dict) and all(
            _is_int(run.get(key, 0)) and run.get(key, 0) >= 0
            for key in ("transitions", "episodes"))):
        problems.append("run is neither null nor a run record with whole numbers of "
                        "transitions and episodes")
    return problems


def report_problems(report: dict[str, Any], actor_bytes: bytes, measured: dict[str, Any] | None,
                    forbidden_sha256: tuple[str, ...] = ()) -> list[str]:
    """Why a report does not describe its actor (an empty list: it does).

    Args:
        report: the handed-in report.
        actor_bytes: the handed-in actor file.
        measured: :func:`evaluate_graded` of that actor file, run by the grader (None: not
            run, e.g. because an earlier check already failed).
        forbidden_sha256: actor files that are not the student's own (the shipped actors:
            refused before any simulation; :func:`likeness_problems` refuses those that
            merely behave like them).
    """
    digest = hashlib.sha256(actor_bytes).hexdigest()
    if digest in forbidden_sha256:
        return ["the handed-in actor is a shipped agent (data/checkpoints), not yours: "
                "train your own in lesson 9 and hand it in"]
    problems = report_type_problems(report)
    if problems:
        return ["the report is malformed: " + "; ".join(problems)]
    if report["actor_sha256"] != digest:
        problems.append(f"the report is of another actor file (sha256 "
                        f"{report['actor_sha256'][:12]}..., the handed-in actor.pt "
                        f"is {digest[:12]}...): write the report again with the actor you "
                        "hand in")
    if report.get("protocol") != GRADED_PROTOCOL:
        problems.append(f"the report's protocol {str(report.get('protocol'))[:200]} is not the "
                        f"graded one {GRADED_PROTOCOL}")
    goals = report["goals"]
    claimed_done = [g["done"] for g in goals]
    claimed_distance = [float(g["final_distance"]) for g in goals]
    claimed_percent = float(report["done_percent"])
    if not math.isclose(claimed_percent, 100.0 * sum(claimed_done) / len(goals),
                        abs_tol=1e-6):
        problems.append(f"done % {claimed_percent:g} does not follow from the goals' done "
                        f"flags ({sum(claimed_done)} of {len(goals)})")
    if measured is None:
        return problems
    if measured["n_nodes"] != report["n_nodes"]:
        problems.append(f"n_nodes: reported {report['n_nodes']}, the actor has "
                        f"{measured['n_nodes']}")
    for claim_done, claim_distance, mine in zip(claimed_done, claimed_distance,
                                                measured["goals"]):
        if claim_done != mine["done"] or not abs(claim_distance - mine["final_distance"]) \
                <= DISTANCE_TOLERANCE:
            problems.append(f"goal {mine['goal_index']}: reported done={claim_done}, final "
                            f"distance {claim_distance:.4f} m; the grader measured "
                            f"done={mine['done']}, {mine['final_distance']:.4f} m")
    if not math.isclose(claimed_percent, measured["done_percent"], abs_tol=1e-6):
        problems.append(f"done %: reported {claimed_percent:g}, the grader measured "
                        f"{measured['done_percent']:g}")
    return problems


def measured_fields(measured: dict[str, Any], report_matches: bool) -> dict[str, Any]:
    """What the grader measured of a handed-in actor (:func:`evaluate_graded`), as the grades
    record it for the class CSV (:func:`csv_fields`): plain numbers only."""
    return {"done_percent": float(measured["done_percent"]),
            "mean_distance": float(np.mean([g["final_distance"] for g in measured["goals"]])),
            "do_nothing_distance": float(np.mean(measured["do_nothing_distances"])),
            "report_matches": bool(report_matches)}


CSV_COLUMNS = ("measured_done_percent", "measured_distance", "do_nothing_distance",
               "report_verified", "claimed_done_percent", "claimed_run_transitions",
               "claimed_run_episodes")
"""The class CSV's columns of each student's hand-in (:func:`csv_fields`): first what the
grader measured itself, then what the student's report claims and nothing checks."""


def csv_fields(folder: str | Path | None, measured: dict[str, Any] | None) -> dict[str, Any]:
    """A student's columns of the class CSV (:data:`CSV_COLUMNS`).

    Measured by the grader at grading time (``measured``: :func:`measured_fields`, None when
    the actor was not evaluated): ``measured_done_percent`` and ``measured_distance`` (its
    mean final distance, m) on the graded protocol, ``do_nothing_distance`` (m, the same
    goals without moving), ``report_verified`` (1 if the report says what the grader
    measured, 0 if not, empty when not evaluated). Claimed by the student's report, not
    checked: ``claimed_done_percent``, ``claimed_run_transitions``, ``claimed_run_episodes``.
    Empty strings where something is missing; never raises, whatever the folder holds."""
    fields: dict[str, Any] = dict.fromkeys(CSV_COLUMNS, "")
    if isinstance(measured, dict):
        for column, key in (("measured_done_percent", "done_percent"),
                            ("measured_distance", "mean_distance"),
                            ("do_nothing_distance", "do_nothing_distance")):
            if _is_number(measured.get(key)):
                fields[column] = round(float(measured[key]), 4)
        if isinstance(measured.get("report_matches"), bool):
            fields["report_verified"] = int(measured["report_matches"])
    if folder is None:
        return fields
    try:
        report, _ = read_submission(folder)
    except (SubmissionError, OSError):
        return fields
    if _is_number(report.get("done_percent")):
        fields["claimed_done_percent"] = float(report["done_percent"])
    run = report.get("run")
    if isinstance(run, dict):
        for column, key in (("claimed_run_transitions", "transitions"),
                            ("claimed_run_episodes", "episodes")):
            if _is_int(run.get(key)):
                fields[column] = run[key]
    return fields
