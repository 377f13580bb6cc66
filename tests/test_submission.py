"""Lesson 13's hand-in (dlo_course.submission): the report of the graded protocol, the
grader that evaluates the handed-in actor again, and what earns the points: an agent the
student trained (2 nodes, behaving like no shipped actor, above the learning floor) with a
report that says what it does. Real actors, real PyBullet.

The floor and the likeness tolerance are never compared here with a number measured once on
a shipped agent (the scene and the agents change): the grader measures doing nothing on the
same goals at grading time, and ``benchmarks/own_agent_floor.py`` says why the lines sit
where they do.
"""

from __future__ import annotations

import copy
import csv
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from dlo_course import submission
from dlo_course.ddpg import Actor, load_network, save_network
from dlo_course.evaluation import load_actor
from dlo_course.grading.grade import grade, leaderboard_markdown
from dlo_course.grading.notebooks import GRADING_TESTS_DIR
from dlo_course.paths import AGENTS_DIR, REPO_ROOT
from dlo_course.rundir import read_progress
from dlo_course.task import observation_size

CAPSTONE = "13_capstone_table_one"
SHIPPED2 = AGENTS_DIR / "nodes2" / submission.ACTOR_NAME



def one_weight(actor):
    """Change one weight of ``actor`` by 1e-6 (a hand-in that is the shipped actor nudged)."""
    next(actor.net.parameters()).view(-1)[0] += 1e-6


def scaled(actor):
    """Scale every weight of ``actor`` by 1.0001 (the shipped actor, rescaled)."""
    for value in actor.state_dict().values():
        if value.is_floating_point():
            value.mul_(1.0001)

def fresh_actor(path: Path, seed: int) -> Path:
    torch.manual_seed(seed)
    save_network(Actor(observation_size(2), 3), path)
    return path


def changed_actor(source: Path, dest: Path, change) -> Path:
    """``source``'s actor with ``change(actor)`` applied to it in place, saved to ``dest``."""
    actor = load_network(source)
    with torch.no_grad():
        change(actor)
    save_network(actor, dest)
    return dest


def run_of(actor: Path, folder: Path) -> Path:
    """A run directory holding ``actor`` beside the shipped 2-node run's configuration and
    learning curve: what lesson 9 leaves."""
    folder.mkdir(parents=True)
    shutil.copyfile(actor, folder / submission.ACTOR_NAME)
    for name in ("config.json", "progress.csv"):
        shutil.copyfile(AGENTS_DIR / "nodes2" / name, folder / name)
    return folder


@pytest.fixture(scope="module")
def handed_in(tmp_path_factory):
    """(folder, report): a hand-in of a freshly initialised actor, written by the library."""
    root = tmp_path_factory.mktemp("submission")
    run = run_of(fresh_actor(root / "fresh.pt", seed=13), root / "run")
    folder = root / submission.SUBMISSION_DIR
    return folder, submission.write_submission(run, folder)


def measured_of(report):
    """What evaluate_graded returned when the report was written."""
    return {key: copy.deepcopy(report[key]) for key in ("n_nodes", "goals", "done_percent")}


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_an_untrained_actor_is_below_the_floor(handed_in):
    """The floor is measured against doing nothing, on the same goals, by the same run: a
    fresh actor's outputs are near zero, so it ends about where doing nothing leaves the rod,
    and no goal of the graded protocol is within reach of the start."""
    _, report = handed_in
    measured = dict(measured_of(report), do_nothing_distances=None)
    again = submission.evaluate_graded(Path(handed_in[0]) / submission.ACTOR_NAME)
    assert again["goals"] == report["goals"]  # deterministic
    assert all(d > submission.GRADED_PROTOCOL["threshold"]
               for d in again["do_nothing_distances"])
    measured["do_nothing_distances"] = again["do_nothing_distances"]
    (problem,) = submission.floor_problems(measured)
    assert "learned too little" in problem


def test_the_floor_is_a_share_of_what_doing_nothing_leaves():
    goals = [{"goal_index": i, "done": False, "final_distance": d, "steps": 6}
             for i, d in zip(submission.GRADED_PROTOCOL["goal_indices"], (0.1, 0.1, 0.1, 0.1))]
    measured = {"n_nodes": 2, "goals": goals, "done_percent": 0.0,
                "do_nothing_distances": [0.15, 0.15, 0.15, 0.15]}
    assert submission.floor_problems(measured) == []  # 0.1 <= 0.75 x 0.15
    for goal in goals:
        goal["final_distance"] = 0.13
    assert "learned too little" in submission.floor_problems(measured)[0]
    goals[0]["final_distance"] = float("nan")  # an unstable rod is not above the floor
    assert submission.floor_problems(measured)


def test_actors_that_behave_like_a_shipped_one_are_refused_whatever_their_bytes(tmp_path):
    """The student's attempts of issue 37, without simulation: a shipped actor changed by
    1e-6, scaled by 1.0001, loaded and saved again, or with a byte appended behaves like the
    shipped one; a 2-node seed's agent behaves like itself; a 4- or 6-node seed's agent has
    the wrong node count; a fresh actor behaves like none of them."""

    attempts = [changed_actor(SHIPPED2, tmp_path / "w.pt", one_weight),
                changed_actor(SHIPPED2, tmp_path / "s.pt", scaled),
                changed_actor(SHIPPED2, tmp_path / "resaved.pt", lambda actor: None)]
    appended = tmp_path / "appended.pt"
    appended.write_bytes(SHIPPED2.read_bytes() + b"\0")
    attempts.append(appended)
    for path in attempts:
        assert submission.sha256_of(path) != submission.sha256_of(SHIPPED2)
        (problem,) = submission.likeness_problems(submission.actor_behaviour(path))
        assert "behaves like the shipped checkpoints/nodes2/actor.pt" in problem, path.name
    seeds = sorted((AGENTS_DIR / "seeds").rglob(submission.ACTOR_NAME))
    assert seeds and set(seeds) <= set(submission.shipped_actor_files())

    nodes = {p: load_actor(p)[1] for p in seeds}  # as the grader reads it: from the actor
    two = next(p for p in seeds if nodes[p] == 2)  # issue 36's 2-node seeds
    (problem,) = submission.likeness_problems(submission.actor_behaviour(two))
    assert f"behaves like the shipped checkpoints/{two.parent.relative_to(AGENTS_DIR)}/" in problem
    other = next(p for p in seeds if nodes[p] != 2)
    (problem,) = submission.likeness_problems(submission.actor_behaviour(other))
    assert "lesson 9 trains a 2-node agent" in problem
    fresh = submission.actor_behaviour(fresh_actor(tmp_path / "fresh.pt", seed=13))
    assert submission.likeness_problems(fresh) == []
    assert all(d > 2 * submission.LIKENESS_TOLERANCE
               for _, d in submission.shipped_likeness(fresh["probe_actions"], 2))


def test_the_probe_observations_are_fixed_and_real():
    first, again = submission.probe_observations(2), submission.probe_observations(2)
    assert first.shape == (submission.PROBE_COUNT, observation_size(2))
    assert np.array_equal(first, again) and np.isfinite(first).all()
    assert not np.array_equal(first, submission.probe_observations(2, seed=1))
    assert len(np.unique(first[:, -6:], axis=0)) > submission.PROBE_COUNT // 2  # many goals


# ------------------------------------------------------------------ malformed hand-ins


def valid_report(actor: bytes) -> dict:
    """A well-formed, self-consistent report of ``actor`` (a made-up result)."""
    import hashlib

    goals = [{"goal_index": i, "done": False, "final_distance": 0.12, "steps": 6}
             for i in submission.GRADED_PROTOCOL["goal_indices"]]
    return {"format": submission.REPORT_FORMAT, "protocol": dict(submission.GRADED_PROTOCOL),
            "n_nodes": 2, "actor_sha256": hashlib.sha256(actor).hexdigest(), "goals": goals,
            "done_percent": 0.0, "run": {"transitions": 6000, "episodes": 50}}


def deep(levels: int) -> str:
    return '{"goals": ' + "[" * levels + "]" * levels + "}"


SECRET = "instructor-secret.txt"  # beside the student's folders: never read, never told


def malform(folder: Path, how: str, secret: Path) -> None:
    """Make the hand-in ``folder`` (a valid one) malformed in one way (a link points to
    ``secret``, a file of the grader's machine)."""
    report, actor = folder / submission.REPORT_NAME, folder / submission.ACTOR_NAME
    good = json.loads(report.read_text())
    if how == "deep nesting":
        report.write_text(deep(100_000))
    elif how == "huge report":
        report.write_text(json.dumps(dict(good, padding="x" * submission.MAX_REPORT_BYTES)))
    elif how == "huge actor":
        with actor.open("ab") as f:
            f.truncate(submission.MAX_ACTOR_BYTES + 1)  # sparse: no disk used
    elif how == "binary report":
        report.write_bytes(bytes(range(256)) * 8)
    elif how == "linked actor":
        actor.unlink()
        actor.symlink_to(secret)
    elif how == "linked report":
        report.unlink()
        report.symlink_to(secret)
    elif how == "linked folder":
        shutil.rmtree(folder)
        folder.symlink_to(secret.parent)
    elif how == "fifo actor":
        actor.unlink()
        os.mkfifo(actor)
    elif how == "NaN":
        report.write_text(json.dumps(good).replace('"final_distance": 0.12', '"final_distance": NaN', 1))
    elif how == "infinite done %":
        report.write_text(json.dumps(good).replace('"done_percent": 0.0', '"done_percent": 1e999'))
    elif how == "wrong types":
        good["goals"][1]["done"] = "yes"
        good["goals"][2]["final_distance"] = "0.1"
        good["n_nodes"] = [2]
        good["run"] = {"transitions": "a lot"}
        report.write_text(json.dumps(good))
    elif how == "missing fields":
        report.write_text(json.dumps({"format": 1, "actor_sha256": good["actor_sha256"]}))
    elif how == "not an object":
        report.write_text(json.dumps([good]))
    elif how == "actor is a folder":
        actor.unlink()
        actor.mkdir()
    else:
        raise ValueError(how)


MALFORMED = ("deep nesting", "huge report", "huge actor", "binary report", "linked actor",
             "linked report", "linked folder", "fifo actor", "NaN", "infinite done %",
             "wrong types", "missing fields", "not an object", "actor is a folder")


def make_hand_in(root: Path, actor: Path) -> Path:
    folder = root / submission.SUBMISSION_DIR
    folder.mkdir(parents=True)
    shutil.copyfile(actor, folder / submission.ACTOR_NAME)
    data = (folder / submission.ACTOR_NAME).read_bytes()
    (folder / submission.REPORT_NAME).write_text(json.dumps(valid_report(data)))
    return folder


@pytest.mark.parametrize("how", MALFORMED)
def test_a_malformed_hand_in_is_refused_with_a_reason_and_never_raises_more(tmp_path, how):
    """Each way is a SubmissionError or a report problem (that student's 0, with a reason),
    never another exception; the class CSV's fields of it are read without raising, and a
    link's target is neither read nor told."""
    (tmp_path / SECRET).write_text("the answer is 42\n")
    folder = make_hand_in(tmp_path / "class" / "student", SHIPPED2)
    malform(folder, how, tmp_path / SECRET)
    try:
        report, actor = submission.read_submission(folder)
    except submission.SubmissionError as err:
        reason = str(err)
        assert submission.sha256_of(tmp_path / SECRET)[:8] not in reason and "42" not in reason
    else:
        problems = submission.report_problems(report, actor, None)
        assert problems and problems[0].startswith("the report is malformed"), (how, problems)
    fields = submission.csv_fields(folder, None)
    assert set(fields) == set(submission.CSV_COLUMNS)
    assert all(v == "" or isinstance(v, (int, float)) for v in fields.values())


def test_a_well_formed_report_passes_the_type_checks(tmp_path):
    folder = make_hand_in(tmp_path, SHIPPED2)
    report, actor = submission.read_submission(folder)
    assert submission.report_type_problems(report) == []
    assert submission.report_problems(report, actor, None) == []
    assert submission.csv_fields(folder, None)["claimed_run_transitions"] == 6000


# ------------------------------------------------------------------ a class, graded


def one_class(students: Path, catalog: Path, names, hand_ins: dict[str, Path]) -> None:
    notebook = REPO_ROOT / "solutions" / f"{CAPSTONE}.ipynb"
    catalog.mkdir(exist_ok=True)
    shutil.copyfile(notebook, catalog / notebook.name)
    for name in names:
        (students / name).mkdir(parents=True)
        shutil.copyfile(notebook, students / name / notebook.name)
        if name in hand_ins:
            shutil.copytree(hand_ins[name], students / name / submission.SUBMISSION_DIR,
                            symlinks=True)


@pytest.mark.slow
def test_the_grader_measures_the_agent_and_fills_the_class_csv(
        trained_hand_in, data_without_the_2_node_agent, tmp_path, monkeypatch):
    """Through `dlo-course course grade`'s own function, lesson 13 only, in an installation
    that does not ship the 2-node agent (so that it is an agent of the student's): an honest
    hand-in of an agent that learned earns the points; distances edited after the evaluation
    or an actor swapped after the report earn none; a student whose hand-in is malformed
    (nested 100 000 deep, a link) gets 0 with a reason, and the class is graded to its end
    with the others' points as they would be alone. The CSV and the leaderboard say what the
    grader measured and what the reports claim."""
    folder, report = trained_hand_in
    (tmp_path / SECRET).write_text("the answer is 42\n")
    monkeypatch.setenv("DLO_COURSE_DATA", str(data_without_the_2_node_agent))
    students = tmp_path / "students"
    names = ("deep", "edited", "honest", "linked", "swapped")
    one_class(students, tmp_path / "catalog", names, dict.fromkeys(names, folder))
    edited = copy.deepcopy(report)
    for goal in edited["goals"]:
        goal["final_distance"] -= 0.002  # closer, not close enough to change a done flag
    (students / "edited" / folder.name / submission.REPORT_NAME).write_text(json.dumps(edited))
    fresh_actor(students / "swapped" / folder.name / submission.ACTOR_NAME, seed=15)
    malform(students / "deep" / folder.name, "deep nesting", tmp_path / SECRET)
    (students / "linked" / folder.name / submission.ACTOR_NAME).unlink()
    (students / "linked" / folder.name / submission.ACTOR_NAME).symlink_to(tmp_path / SECRET)

    out = tmp_path / "grades.csv"
    graded = grade(students, out, GRADING_TESTS_DIR / f"test_{CAPSTONE}.py",
                   catalog=tmp_path / "catalog", progress=False)
    with out.open(newline="", encoding="utf-8") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    assert list(rows) == list(names)
    assert {name: float(row["own_agent_report"]) for name, row in rows.items()} == {
        "deep": 0, "edited": 0, "honest": 2, "linked": 0, "swapped": 0}
    # the rest, unchanged: the written answers' points pending the instructor's review
    others = {name: float(row["total"]) + float(row["pending"]) - float(row["own_agent_report"])
              for name, row in rows.items()}
    assert len(set(others.values())) == 1 and others["honest"] > 0
    assert {name: row["report_verified"] for name, row in rows.items()} == {
        "deep": "", "edited": "0", "honest": "1", "linked": "", "swapped": ""}
    honest = rows["honest"]
    assert float(honest["measured_done_percent"]) == report["done_percent"]
    assert float(honest["measured_distance"]) == pytest.approx(
        np.mean([g["final_distance"] for g in report["goals"]]), abs=1e-4)
    assert float(honest["measured_distance"]) <= \
        submission.FLOOR_SHARE * float(honest["do_nothing_distance"])
    assert int(honest["claimed_run_transitions"]) == report["run"]["transitions"]
    assert rows["edited"]["measured_done_percent"] == honest["measured_done_percent"]
    assert rows["deep"]["claimed_done_percent"] == rows["linked"]["measured_distance"] == ""
    feedback = tmp_path / "grades_feedback"
    assert "the grader measured" in (feedback / "edited.md").read_text()
    assert "another actor file" in (feedback / "swapped.md").read_text()
    assert "nested more than" in (feedback / "deep.md").read_text()
    linked = (feedback / "linked.md").read_text()
    assert "symbolic link" in linked
    assert submission.sha256_of(tmp_path / SECRET)[:8] not in linked and "42" not in linked
    board = leaderboard_markdown(graded).splitlines()
    table = [line.split(" | ") for line in board if line.startswith("| ") and
             line[2].isdigit()]
    assert [cells[1] for cells in table] == ["honest", "edited", "deep", "linked", "swapped"]
    assert table[0][2] == "yes" and table[1][2] == "no"
    assert "Measured" in board[0] and "Claimed" in board[0]
    header = next(line for line in board if line.startswith("| # "))
    assert "done % (measured)" in header and "transitions (claimed)" in header


def test_the_leaderboard_puts_accepted_agents_first_and_says_what_was_measured():
    rows = [{"student": "ann", "own_agent_report": 0, "claimed_done_percent": 100.0,
             "measured_done_percent": 0.0, "measured_distance": 0.15, "report_verified": 0},
            {"student": "bea", "own_agent_report": 2, "claimed_done_percent": 50.0,
             "measured_done_percent": 50.0, "measured_distance": 0.06,
             "do_nothing_distance": 0.158, "report_verified": 1},
            {"student": "cy", "own_agent_report": 0, "claimed_done_percent": "",
             "measured_done_percent": ""},
            {"student": "dan", "own_agent_report": 2, "claimed_done_percent": 75.0,
             "measured_done_percent": 75.0, "measured_distance": 0.048,
             "do_nothing_distance": 0.158, "report_verified": 1,
             "claimed_run_transitions": 9000, "claimed_run_episodes": 150}]
    board = leaderboard_markdown(rows).splitlines()
    table = [line for line in board if line.startswith("| ") and line[2].isdigit()]
    assert [line.split(" | ")[1] for line in table] == ["dan", "bea", "ann", "cy"]
    assert table[0] == "| 1 | dan | yes | 75 | 0.048 | 0.158 | yes | 75 | 9000 | 150 |"
    assert table[2] == "| 3 | ann | no | 0 | 0.150 |  | no | 100 |  |  |"
    assert table[3] == "| 4 | cy | no |  |  |  |  |  |  |  |"


@pytest.mark.slow
def test_the_attempts_of_issue_37_score_zero_through_course_grade(trained_hand_in, tmp_path):
    """As a student who wants the points without training would try, each through the real
    `dlo-course course grade` on the lesson 13 notebook of a released student bundle: the
    shipped 2-node actor with one weight changed by 1e-6, all weights scaled by 1.0001,
    loaded and saved again, or with a byte appended (each with a report made consistent with
    its bytes, or the shipped actor's real report unchanged); a seed's agent unchanged; an
    untrained actor with its honest report. Every one scores 0, and the leaderboard accepts
    none of them."""
    from click.testing import CliRunner

    from dlo_course.cli import main
    from dlo_course.grading.bundle import release_student

    bundle = tmp_path / "bundle"
    release_student(bundle)
    notebook = bundle / "lessons" / f"{CAPSTONE}.ipynb"
    folder, shipped_report = trained_hand_in
    actors = tmp_path / "actors"
    actors.mkdir()


    appended = actors / "appended.pt"
    appended.write_bytes(SHIPPED2.read_bytes() + b"\n")
    seed = sorted((AGENTS_DIR / "seeds").rglob(submission.ACTOR_NAME))[0]
    disguised = {"nudged": changed_actor(SHIPPED2, actors / "w.pt", one_weight),
                 "scaled": changed_actor(SHIPPED2, actors / "s.pt", scaled),
                 "resaved": changed_actor(SHIPPED2, actors / "r.pt", lambda actor: None),
                 "appended": appended, "seed": seed}
    students = tmp_path / "class"
    for name, actor in disguised.items():
        hand_in = students / name / submission.SUBMISSION_DIR
        hand_in.mkdir(parents=True)
        shutil.copyfile(actor, hand_in / submission.ACTOR_NAME)
        report = dict(shipped_report, actor_sha256=submission.sha256_of(actor))
        (hand_in / submission.REPORT_NAME).write_text(json.dumps(report))
    shutil.copytree(folder, students / "shipped_report" / submission.SUBMISSION_DIR)
    shutil.copyfile(disguised["nudged"], students / "shipped_report" / submission.SUBMISSION_DIR
                    / submission.ACTOR_NAME)
    untrained = run_of(fresh_actor(actors / "fresh.pt", seed=3), tmp_path / "untrained_run")
    honest = submission.write_submission(untrained, students / "untrained" /
                                         submission.SUBMISSION_DIR)
    assert honest["done_percent"] == 0  # its honest report: nothing reached
    for student in students.iterdir():
        shutil.copyfile(notebook, student / notebook.name)

    out = tmp_path / "grades.csv"
    result = CliRunner().invoke(main, [
        "course", "grade", str(students), "--out", str(out), "--jobs", "2",
        "--leaderboard", str(tmp_path / "agents.md")])
    assert result.exit_code == 0, result.output
    with out.open(newline="", encoding="utf-8") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    assert sorted(rows) == sorted([*disguised, "shipped_report", "untrained"])
    assert {name: float(row["own_agent_report"]) for name, row in rows.items()} == \
        dict.fromkeys(rows, 0.0)
    sheets = {name: (tmp_path / "grades_feedback" / f"{name}.md").read_text() for name in rows}
    for name in ("nudged", "scaled", "resaved", "appended"):
        assert "behaves like the shipped checkpoints/nodes2/actor.pt" in sheets[name], name
    assert "shipped agent" in sheets["seed"]
    assert "another actor file" in sheets["shipped_report"]
    assert "learned too little" in sheets["untrained"]
    assert rows["untrained"]["report_verified"] == "1"  # honest, and still no points
    board = (tmp_path / "agents.md").read_text().splitlines()
    table = [line.split(" | ") for line in board if line.startswith("| ") and line[2].isdigit()]
    assert len(table) == len(rows) and all(cells[2] == "no" for cells in table)
