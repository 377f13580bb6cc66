"""Lesson 13's hand-in (dlo_course.submission): the report of the graded protocol, and the
grader that evaluates the handed-in actor again and gives 0 to a report that does not say
what the actor does, or to the shipped agent. Real actors, real PyBullet: one evaluation
when the hand-in is written, and one per honest-looking report the grader checks."""

from __future__ import annotations

import copy
import csv
import json
import shutil
from pathlib import Path

import pytest
import torch

from dlo_course import submission
from dlo_course.ddpg import Actor, save_network
from dlo_course.grading.grade import grade, leaderboard_markdown
from dlo_course.grading.notebooks import GRADING_TESTS_DIR
from dlo_course.paths import AGENTS_DIR, REPO_ROOT
from dlo_course.rundir import read_progress
from dlo_course.task import observation_size

CAPSTONE = "13_capstone_table_one"


def fresh_actor(path: Path, seed: int) -> Path:
    torch.manual_seed(seed)
    save_network(Actor(observation_size(2), 3), path)
    return path


@pytest.fixture(scope="module")
def handed_in(tmp_path_factory):
    """(folder, report): a hand-in of a freshly initialised actor, from a run directory that
    holds it beside the shipped 2-node run's configuration and learning curve."""
    root = tmp_path_factory.mktemp("submission")
    run = root / "run"
    run.mkdir()
    fresh_actor(run / "actor.pt", seed=13)
    for name in ("config.json", "progress.csv"):
        shutil.copyfile(AGENTS_DIR / "nodes2" / name, run / name)
    folder = root / submission.SUBMISSION_DIR
    return folder, submission.write_submission(run, folder)


def measured_of(report):
    """What evaluate_graded returned when the report was written."""
    return {key: copy.deepcopy(report[key]) for key in ("n_nodes", "goals", "done_percent")}


def test_the_report_holds_the_protocol_results_and_the_run_record(handed_in):
    folder, report = handed_in
    assert json.loads((folder / submission.REPORT_NAME).read_text()) == report
    assert report["protocol"] == submission.GRADED_PROTOCOL and report["n_nodes"] == 2
    assert report["actor_sha256"] == submission.sha256_of(folder / submission.ACTOR_NAME)
    goals = report["goals"]
    assert [g["goal_index"] for g in goals] == submission.GRADED_PROTOCOL["goal_indices"]
    for goal in goals:
        assert 0 < goal["final_distance"] < 1
        assert 1 <= goal["steps"] <= submission.GRADED_PROTOCOL["max_steps"]
        assert goal["done"] == (goal["final_distance"] < 0.05)
    assert report["done_percent"] == 100 * sum(g["done"] for g in goals) / len(goals)
    progress = read_progress(AGENTS_DIR / "nodes2")
    run = report["run"]
    assert (run["episodes"], run["transitions"]) == (int(progress["episode"][-1]),
                                                     int(progress["transitions"][-1]))
    assert run["wall_time_s"] == pytest.approx(float(progress["wall_time"][-1]))
    assert run["config"] == json.loads((AGENTS_DIR / "nodes2" / "config.json").read_text())
    report_again, actor = submission.read_submission(folder)
    assert report_again == report
    assert submission.report_problems(report, actor, measured_of(report)) == []


def test_a_report_edited_by_hand_does_not_match(handed_in):
    folder, report = handed_in
    _, actor = submission.read_submission(folder)
    measured = measured_of(report)
    edited = copy.deepcopy(report)
    edited["done_percent"] = 25.0  # the done % alone
    assert any("done %" in p for p in submission.report_problems(edited, actor, measured))
    edited["goals"][0]["done"] = not edited["goals"][0]["done"]  # flags and % agree now
    edited["done_percent"] = 100 * sum(g["done"] for g in edited["goals"]) / 4
    problems = submission.report_problems(edited, actor, measured)
    assert any("goal 0" in p for p in problems) and any("done %" in p for p in problems)
    edited = copy.deepcopy(report)
    edited["goals"][2]["final_distance"] -= 0.002  # 2 mm closer than it got
    assert any("goal 32" in p for p in submission.report_problems(edited, actor, measured))
    edited["goals"][2]["final_distance"] += 0.0015  # within the grader's tolerance
    assert submission.report_problems(edited, actor, measured) == []


def test_another_actor_or_the_shipped_agent_does_not_match(handed_in, tmp_path):
    folder, report = handed_in
    other = fresh_actor(tmp_path / "other.pt", seed=14).read_bytes()
    assert any("another actor file" in p
               for p in submission.report_problems(report, other, None))
    shipped = (AGENTS_DIR / "nodes2" / "actor.pt").read_bytes()
    forged = dict(report, actor_sha256=submission.sha256_of(AGENTS_DIR / "nodes2" / "actor.pt"))
    problems = submission.report_problems(forged, shipped, None,
                                          (forged["actor_sha256"],))
    assert len(problems) == 1 and "shipped agent" in problems[0]


def test_read_submission_says_what_is_missing(tmp_path):
    with pytest.raises(submission.SubmissionError, match="no report.json and no actor.pt"):
        submission.read_submission(tmp_path)
    (tmp_path / submission.ACTOR_NAME).write_bytes(b"x")
    (tmp_path / submission.REPORT_NAME).write_text("{not json")
    with pytest.raises(submission.SubmissionError, match="not readable JSON"):
        submission.read_submission(tmp_path)
    (tmp_path / submission.REPORT_NAME).write_text("{}")
    (tmp_path / submission.ACTOR_NAME).write_bytes(b"\0" * (submission.MAX_ACTOR_BYTES + 1))
    with pytest.raises(submission.SubmissionError, match="not an actor file"):
        submission.read_submission(tmp_path)


def test_the_grader_evaluates_the_actor_again_and_fills_the_class_csv(handed_in, tmp_path):
    """Through `dlo-course course grade`'s own function, lesson 13 only: an honest hand-in
    earns the points; distances edited after the evaluation, or an actor swapped after the
    report, earn none; the CSV says which claims were verified."""
    folder, report = handed_in
    catalog = tmp_path / "catalog"
    catalog.mkdir()
    notebook = REPO_ROOT / "solutions" / f"{CAPSTONE}.ipynb"
    shutil.copyfile(notebook, catalog / notebook.name)
    students = tmp_path / "students"
    for name in ("honest", "edited", "swapped"):
        (students / name).mkdir(parents=True)
        shutil.copyfile(notebook, students / name / notebook.name)
        shutil.copytree(folder, students / name / folder.name)
    edited = copy.deepcopy(report)
    for goal in edited["goals"]:
        goal["final_distance"] -= 0.01  # closer, not close enough to change a done flag
    (students / "edited" / folder.name / submission.REPORT_NAME).write_text(json.dumps(edited))
    fresh_actor(students / "swapped" / folder.name / submission.ACTOR_NAME, seed=15)

    out = tmp_path / "grades.csv"
    graded = grade(students, out, GRADING_TESTS_DIR / f"test_{CAPSTONE}.py", catalog=catalog,
                   progress=False)
    with out.open(newline="", encoding="utf-8") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    assert {name: float(row["own_agent_report"]) for name, row in rows.items()} == {
        "honest": 2, "edited": 0, "swapped": 0}
    assert {name: row["done_verified"] for name, row in rows.items()} == {
        "honest": "1", "edited": "0", "swapped": "0"}
    assert all(float(row["claimed_done_percent"]) == report["done_percent"]
               for row in rows.values())
    assert all(int(row["run_transitions"]) == report["run"]["transitions"]
               for row in rows.values())
    feedback = tmp_path / "grades_feedback"
    assert "the grader measured" in (feedback / "edited.md").read_text()
    assert "another actor file" in (feedback / "swapped.md").read_text()
    board = leaderboard_markdown(graded).splitlines()
    assert [line.split(" | ")[1] for line in board[2:]] == ["honest", "edited", "swapped"]
    assert board[2].split(" | ")[3] == "yes" and board[3].split(" | ")[3] == "no"


def test_the_leaderboard_puts_verified_claims_first():
    rows = [{"student": "ann", "claimed_done_percent": 100.0, "done_verified": 0},
            {"student": "bea", "claimed_done_percent": 50.0, "done_verified": 1},
            {"student": "cy", "claimed_done_percent": "", "done_verified": 0},
            {"student": "dan", "claimed_done_percent": 75.0, "done_verified": 1,
             "run_transitions": 9000, "run_episodes": 150}]
    board = leaderboard_markdown(rows).splitlines()
    assert [line.split(" | ")[1] for line in board[2:]] == ["dan", "bea", "ann", "cy"]
    assert board[2] == "| 1 | dan | 75 | yes | 9000 | 150 |"
    assert board[5] == "| 4 | cy |  | no |  |  |"
