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


def evaluate_graded(agent: str | Path, protocol: dict[str, Any] | None = None
                    ) -> dict[str, Any]:
    """Run the graded protocol on a trained agent (:func:`dlo_course.evaluation.load_actor`).

    Returns:
        ``{"n_nodes": int, "goals": [{"goal_index", "done", "final_distance", "steps"}, ...],
        "done_percent": float}``, the goals in protocol order.
    """
    from dlo_course.database import resolve_goals
    from dlo_course.env import make_env
    from dlo_course.evaluation import EpisodeTrace, _play, load_actor

    protocol = dict(GRADED_PROTOCOL if protocol is None else protocol)
    actor, n_nodes = load_actor(actor_file(agent))
    indices = [int(i) for i in protocol["goal_indices"]]
    threshold = float(protocol["threshold"])
    env = make_env(max_episode_steps=None, n_nodes=n_nodes,
                   goals=resolve_goals(protocol["goals"], n_nodes)[indices],
                   threshold=threshold, time_mode="code")
    goals = []
    try:
        # One world, built and settled once (the costly part); every later episode starts
        # where the previous one stopped, from its new goal at once.
        obs, info = env.reset(options={"reinitialize": True, "goal_index": 0})
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
            "done_percent": 100.0 * done / len(goals)}


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
    """A handed-in folder that cannot be graded (missing, unreadable)."""


def read_submission(folder: str | Path) -> tuple[dict[str, Any], bytes]:
    """The report and the actor file's bytes of a handed-in folder.

    Raises:
        SubmissionError: with what is missing and how to make it.
    """
    folder = Path(folder)
    report_path, actor = folder / REPORT_NAME, folder / ACTOR_NAME
    how = ("run the last cell of lesson 13 (section 11), which writes both, and hand in the "
           f"folder {SUBMISSION_DIR}/ beside the notebook")
    missing = [p.name for p in (report_path, actor) if not p.is_file()]
    if missing:
        raise SubmissionError(f"no {' and no '.join(missing)} in {folder}: {how}")
    if actor.stat().st_size > MAX_ACTOR_BYTES:
        raise SubmissionError(f"{actor} is {actor.stat().st_size / 2**20:.0f} MB, not an actor "
                              f"file of lesson 9 (at most {MAX_ACTOR_BYTES // 2**20} MB): {how}")
    try:
        report = json.loads(report_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise SubmissionError(f"{report_path} is not readable JSON ({err}): {how}") from err
    if not isinstance(report, dict):
        raise SubmissionError(f"{report_path} holds no report object: {how}")
    return report, actor.read_bytes()


def report_problems(report: dict[str, Any], actor_bytes: bytes, measured: dict[str, Any] | None,
                    forbidden_sha256: tuple[str, ...] = ()) -> list[str]:
    """Why a report does not describe its actor (an empty list: it does).

    Args:
        report: the handed-in report.
        actor_bytes: the handed-in actor file.
        measured: :func:`evaluate_graded` of that actor file, run by the grader (None: not
            run, e.g. because an earlier check already failed).
        forbidden_sha256: actors that are not the student's own (the shipped agents).
    """
    digest = hashlib.sha256(actor_bytes).hexdigest()
    if digest in forbidden_sha256:
        return ["the handed-in actor is the shipped agent (data/checkpoints), not yours: "
                "train your own in lesson 9 and hand it in"]
    problems = []
    if report.get("actor_sha256") != digest:
        problems.append(f"the report is of another actor file (sha256 "
                        f"{str(report.get('actor_sha256'))[:12]}..., the handed-in actor.pt "
                        f"is {digest[:12]}...): write the report again with the actor you "
                        "hand in")
    if report.get("protocol") != GRADED_PROTOCOL:
        problems.append(f"the report's protocol {report.get('protocol')} is not the graded "
                        f"one {GRADED_PROTOCOL}")
    goals = report.get("goals")
    if not isinstance(goals, list) or len(goals) != len(GRADED_PROTOCOL["goal_indices"]):
        return problems + ["the report has no result per graded goal"]
    try:
        claimed_done = [bool(g["done"]) for g in goals]
        claimed_distance = [float(g["final_distance"]) for g in goals]
        claimed_percent = float(report["done_percent"])
    except (KeyError, TypeError, ValueError) as err:
        return problems + [f"the report's results are unreadable ({err!r})"]
    if not math.isclose(claimed_percent, 100.0 * sum(claimed_done) / len(goals),
                        abs_tol=1e-6):
        problems.append(f"done % {claimed_percent:g} does not follow from the goals' done "
                        f"flags ({sum(claimed_done)} of {len(goals)})")
    if measured is None:
        return problems
    if measured["n_nodes"] != report.get("n_nodes"):
        problems.append(f"n_nodes: reported {report.get('n_nodes')}, the actor has "
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


def csv_fields(folder: str | Path | None, verified: bool | None) -> dict[str, Any]:
    """A student's columns of the class CSV from their handed-in report: ``claimed_done_percent``,
    ``done_verified`` (1 if the grader's evaluation matched the report, 0 if not, empty when
    not graded), ``run_transitions`` and ``run_episodes``; empty strings where the report (or
    its run record) is missing."""
    fields: dict[str, Any] = dict.fromkeys(CSV_COLUMNS, "")
    if verified is not None:
        fields["done_verified"] = int(bool(verified))
    if folder is None:
        return fields
    try:
        report, _ = read_submission(folder)
    except SubmissionError:
        return fields
    if isinstance(report.get("done_percent"), (int, float)):
        fields["claimed_done_percent"] = float(report["done_percent"])
    run = report.get("run")
    if isinstance(run, dict):
        fields["run_transitions"] = run.get("transitions", "")
        fields["run_episodes"] = run.get("episodes", "")
    return fields


CSV_COLUMNS = ("claimed_done_percent", "done_verified", "run_transitions", "run_episodes")
"""The class CSV's columns from each student's report (:func:`csv_fields`)."""
