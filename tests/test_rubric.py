"""Written answers and their rubrics (issues 30, 51): reading and checking rubrics, releasing
them to the student, and the rule of issue 51: no pattern gives a written answer points. An
answer that is there awaits the instructor's review (its points pending, in the grades, the
class CSV and the feedback sheet) until a reviews file gives them; a missing or too-short
one gets 0, said to the student. The rubric's patterns are a hint for the reviewer.

Everything runs on small real notebooks written to ``tmp_path``, graded by the real grader:
a copy of ``tests/grading/conftest.py`` beside a small grading test file.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import subprocess

import pytest
from click.testing import CliRunner

from dlo_course.cli import main
from dlo_course.grading import notebooks
from dlo_course.grading.grade import PENDING, grade, grading_command
from dlo_course.grading.reviews import read_reviews
from dlo_course.paths import REPO_ROOT

STEM = "98_rubric_demo"  # not a course notebook: the grader falls back to the cell's rubric
RUBRIC = [{"criterion": "commits to a number of cells", "patterns": [r"\d", r"\bnone\b"]},
          {"criterion": "gives a reason", "patterns": [r"\bbecause\b", r"\bsince\b"]}]
NOTE = ("A good answer names a number of cells, for instance 6, and says why, because the "
        "threshold is tight.")
VACUOUS = "As I have not run the cell yet, I cannot say 1 thing about it here."  # issue 51
GRADING_TEST = f'''
import pytest

pytestmark = pytest.mark.notebook("{STEM}")


@pytest.mark.exercise("prediction_cells", points=2)
def test_prediction_cells(written_answer):
    written_answer.check()


@pytest.mark.exercise("analysis_free", points=1)
def test_analysis_free(written_answer):
    written_answer.check()
'''


def answer_cell(name: str, points: int, min_words: int, text: str, rubric=None) -> dict:
    meta = {"answer": name, "points": points, "min_words": min_words}
    if rubric is not None:
        meta["rubric"] = rubric
    first = f"<!-- answer: {name} ({points} points, at least {min_words} words) -->"
    return {"cell_type": "markdown", "id": name.replace("_", "-"),
            "metadata": {"dlo_course": meta}, "source": f"{first}\n{text}"}


def demo_notebook(prediction: str, rubric=RUBRIC, free: str = "Any ten words of my own here "
                  "will do for this free answer.") -> dict:
    cells = [{"cell_type": "markdown", "id": "intro", "metadata": {},
              "source": ["# A rubric demo\n", "\n", "### Predict, then run: how many cells?"]},
             answer_cell("prediction_cells", 2, 10, prediction, rubric),
             {"cell_type": "code", "id": "run", "metadata": {}, "execution_count": None,
              "outputs": [], "source": ["print(6)"]},
             answer_cell("analysis_free", 1, 10, free)]
    return {"cells": cells, "metadata": {}, "nbformat": 4, "nbformat_minor": 5}


def grading_folder(tmp_path):
    """The real grader (a copy of tests/grading/conftest.py) with a test file for the demo."""
    folder = tmp_path / "grading"
    folder.mkdir()
    shutil.copy(notebooks.GRADING_TESTS_DIR / "conftest.py", folder / "conftest.py")
    (folder / f"test_{STEM}.py").write_text(GRADING_TEST)
    return folder


def grade_one(tmp_path, nb: dict) -> dict[str, dict]:
    student = tmp_path / "student"
    notebooks.write_notebook(nb, student / f"{STEM}.ipynb")
    out = tmp_path / "grades.json"
    proc = subprocess.run(grading_command(student, grading_folder(tmp_path), out),
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert out.is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    return {e["exercise"]: e for e in json.loads(out.read_text())["exercises"]}


# ------------------------------------------------------------------ reading and scoring


def test_written_answers_return_their_rubric(tmp_path):
    path = notebooks.write_notebook(demo_notebook(NOTE), tmp_path / f"{STEM}.ipynb")
    answers = notebooks.written_answers(path)
    assert answers["prediction_cells"]["rubric"] == RUBRIC
    assert answers["analysis_free"]["rubric"] == []
    assert "rubric" not in notebooks.answer_info(demo_notebook(NOTE)["cells"][3])


@pytest.mark.parametrize("rubric, message", [
    ({"criterion": "x", "patterns": ["a"]}, "must be a non-empty list"),
    ([], "must be a non-empty list"),
    ([{"criterion": "gives a reason"}], "exactly the keys 'criterion' and 'patterns'"),
    ([{"criterion": "gives a reason", "pattern": ["because"]}], "exactly the keys"),
    ([{"criterion": "", "patterns": ["because"]}], "must be one line of text"),
    ([{"criterion": "gives a reason", "patterns": []}], "'patterns' must be a non-empty list"),
    ([{"criterion": "gives a reason", "patterns": "because"}], "'patterns' must be a non-empty"),
    ([{"criterion": "gives a reason", "patterns": ["(because"]}], "not a valid regular expr"),
    ([{"criterion": "gives a reason", "patterns": ["because|"]}], "matches the empty text"),
])
def test_a_malformed_rubric_names_the_notebook_and_the_answer(tmp_path, rubric, message):
    path = notebooks.write_notebook(demo_notebook(NOTE, rubric), tmp_path / f"{STEM}.ipynb")
    for read in (lambda: notebooks.written_answers(path), lambda: notebooks.exercises(tmp_path),
                 lambda: notebooks.release(tmp_path, tmp_path / "lessons")):
        with pytest.raises(ValueError, match=message) as err:
            read()
        assert f"{STEM}.ipynb" in str(err.value) and "'prediction_cells'" in str(err.value)


def test_patterns_are_a_hint_that_a_vacuous_answer_can_meet():
    rubric = notebooks.check_rubric(RUBRIC, "prediction_cells")
    # the measured defect of issue 51: a digit and "as" meet every criterion of lesson 01's
    # prediction_sweeps, which therefore cannot be what gives its point
    sweeps = notebooks.written_answers(
        notebooks.SOLUTIONS_DIR / "01_rl_and_the_bellman_equation.ipynb")["prediction_sweeps"]
    assert notebooks.rubric_met(VACUOUS, sweeps["rubric"]) == [True, True]
    assert notebooks.rubric_met(VACUOUS, rubric) == [True, False]
    assert notebooks.rubric_met("NONE, SINCE it fails", rubric) == [True, True]  # any case
    assert notebooks.written_answer_problem(VACUOUS, 10) is None  # long enough to be read
    assert "at least 10 words" in notebooks.written_answer_problem("6 because.", 10)
    assert "no answer written" in notebooks.written_answer_problem("", 10)
    assert not hasattr(notebooks, "written_answer_score")  # nothing scores prose


def test_the_grader_gives_no_automatic_points_and_records_the_hints(tmp_path):
    graded = grade_one(tmp_path, demo_notebook(VACUOUS))
    cells, free = graded["prediction_cells"], graded["analysis_free"]
    assert (cells["earned"], cells["pending"], cells["points"]) == (0, 2, 2)
    assert cells["outcome"] == "awaiting review" and cells["text"] == VACUOUS
    assert cells["rubric"] == [
        {"criterion": "commits to a number of cells", "patterns_found": True},
        {"criterion": "gives a reason", "patterns_found": False}]
    assert (free["earned"], free["pending"], free["outcome"]) == (0, 1, "awaiting review")
    assert "rubric" not in free


@pytest.mark.parametrize("answer, pending", [
    ("I expect 6 cells to pass, because the threshold is tight for the six-node rod.", 2),
    ("I expect most of the cells to pass; the threshold looks generous to me here.", 2),
    (VACUOUS, 2),  # issue 51's: no keyword earns it a point
    ("6 cells, because tight.", 0),  # every criterion's pattern, but too short: 0, said
    ("", 0),
])
def test_a_written_answer_is_never_scored_by_a_pattern(tmp_path, answer, pending):
    entry = grade_one(tmp_path, demo_notebook(answer))["prediction_cells"]
    assert entry["earned"] == 0
    assert entry.get("pending", 0) == pending
    assert entry["outcome"] == ("awaiting review" if pending else "failed")
    if not pending:
        assert "at least 10 words" in entry["message"] or "no answer written" in entry["message"]


def test_the_grader_reports_a_malformed_rubric(tmp_path):
    bad = [{"criterion": "gives a reason", "patterns": ["(because"]}]
    graded = grade_one(tmp_path, demo_notebook(NOTE, bad))
    entry = graded["prediction_cells"]
    assert entry["earned"] == 0
    assert f"{STEM}.ipynb" in entry["message"] and "'prediction_cells'" in entry["message"]
    assert "not a valid regular expression" in entry["message"]


# ------------------------------------------------------------------ choices (issue 51)
# Where a prediction is a choice among stated options, the answer is structured and its grade
# automatic: the point for naming exactly one option's letter.

CHOICE_STEM = "96_choice_demo"
OPTIONS = ["the controller wins", "the agent wins", "the intervals cannot tell"]
CHOICE_TEST = f'''
import pytest

pytestmark = pytest.mark.notebook("{CHOICE_STEM}")


@pytest.mark.exercise("prediction_pick", points=1)
def test_prediction_pick(written_answer):
    written_answer.check()
'''


def choice_notebook(text: str) -> dict:
    cell = answer_cell("prediction_pick", 1, 1, text)
    cell["metadata"]["dlo_course"]["choices"] = OPTIONS
    cell["source"] = cell["source"].replace("at least 1 words", "at least 1 word")
    return {"cells": [cell], "metadata": {}, "nbformat": 4, "nbformat_minor": 5}


def grade_choice(tmp_path, text: str) -> dict:
    folder = tmp_path / "grading_choice"
    folder.mkdir()
    shutil.copy(notebooks.GRADING_TESTS_DIR / "conftest.py", folder / "conftest.py")
    (folder / f"test_{CHOICE_STEM}.py").write_text(CHOICE_TEST)
    student = tmp_path / "student"
    notebooks.write_notebook(choice_notebook(text), student / f"{CHOICE_STEM}.ipynb")
    out = tmp_path / "grades.json"
    proc = subprocess.run(grading_command(student, folder, out), cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=300)
    assert out.is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads(out.read_text())["exercises"][0]


def test_chosen_options_are_the_letters_in_brackets():
    assert notebooks.chosen_options("(b), because the probes are early.", OPTIONS) == ["b"]
    assert notebooks.chosen_options("(B) is my bet", OPTIONS) == ["b"]
    assert notebooks.chosen_options("(a) or (c)", OPTIONS) == ["a", "c"]
    assert notebooks.chosen_options("(d), since none fits", OPTIONS) == []  # not an option
    assert notebooks.chosen_options(VACUOUS, OPTIONS) == []
    assert notebooks.chosen_options("b: the agent", OPTIONS) == []
    for bad in (["only one"], ["same", "same"], ["a", ""], "ab", ["two\nlines", "b"]):
        with pytest.raises(ValueError, match="'pick': choices must be a list of 2 to 26"):
            notebooks.check_choices(bad, "pick")


def test_release_lists_the_options_and_the_grader_reads_them_from_the_solution(tmp_path):
    notebooks.write_notebook(choice_notebook("(b) because."),
                             tmp_path / "solutions" / f"{CHOICE_STEM}.ipynb")
    notebooks.release(tmp_path / "solutions", tmp_path / "lessons")
    cell = notebooks.read_notebook(tmp_path / "lessons" / f"{CHOICE_STEM}.ipynb")["cells"][0]
    assert notebooks.cell_source(cell).split("\n") == [
        "<!-- answer: prediction_pick (1 point, at least 1 word) -->",
        notebooks.ANSWER_PLACEHOLDER, "",
        "*Choose one, by its letter:* (a) the controller wins; (b) the agent wins; "
        "(c) the intervals cannot tell"]
    assert notebooks.answer_text(cell) == ""  # the listed options are not a choice
    assert notebooks.answer_info(cell)["choices"] == OPTIONS


@pytest.mark.parametrize("answer, earned, found", [
    ("(b), because the probed Jacobian is measured before the rod follows its tip.", 1, None),
    ("(c)", 1, None),
    ("The agent wins, because the probes come too early.", 0, "found: none"),
    ("(a) or (b), I cannot decide.", 0, "found: (a), (b)"),
    (VACUOUS, 0, "found: none"),
    ("", 0, None),
])
def test_a_choice_is_graded_automatically(tmp_path, answer, earned, found):
    entry = grade_choice(tmp_path, answer)
    assert entry["earned"] == earned and "pending" not in entry
    assert entry["outcome"] == ("passed" if earned else "failed")
    if found:
        assert found in entry["message"] and "(c) the intervals cannot tell" in entry["message"]


def test_the_course_choices_are_met_by_their_solution_and_not_reviewed(tmp_path):
    choices = {name: info for path in notebooks.notebooks_in(notebooks.SOLUTIONS_DIR)
               for name, info in notebooks.written_answers(path).items() if info["choices"]}
    assert set(choices) == {"prediction_controller_vs_agent", "prediction_robustness"}
    for name, info in choices.items():
        assert len(notebooks.chosen_options(info["text"], info["choices"])) == 1, name
        assert not info["rubric"], name  # a choice's grade is its letter, not a checklist
    # a reviews file cannot give a choice points: refused before grading, as no prose answer
    path = tmp_path / "reviews.csv"
    path.write_text("student,exercise,points\nalice,prediction_robustness,1\n")
    (tmp_path / "class" / "alice").mkdir(parents=True)
    result = CliRunner().invoke(main, ["course", "grade", str(tmp_path / "class"), "--out",
                                       str(tmp_path / "g.csv"), "--reviews", str(path)])
    assert result.exit_code != 0
    assert "'prediction_robustness' is not a written answer" in result.output


# ------------------------------------------------------------------ release


def test_release_lists_the_criteria_and_keeps_the_rubric(tmp_path):
    notebooks.write_notebook(demo_notebook(NOTE), tmp_path / "solutions" / f"{STEM}.ipynb")
    notebooks.release(tmp_path / "solutions", tmp_path / "lessons")
    assert notebooks.release(tmp_path / "solutions", tmp_path / "lessons", check=True) == []
    path = tmp_path / "lessons" / f"{STEM}.ipynb"
    assert path.read_text(encoding="utf-8") == notebooks.notebook_json(
        notebooks.read_notebook(path))  # Jupyter's layout
    cell = notebooks.read_notebook(path)["cells"][1]
    assert cell["metadata"]["dlo_course"]["rubric"] == RUBRIC
    source = notebooks.cell_source(cell)
    assert NOTE not in source  # the instructor's note is gone
    assert source.split("\n") == [
        "<!-- answer: prediction_cells (2 points, at least 10 words) -->",
        notebooks.ANSWER_PLACEHOLDER, "",
        "*Checked for:* (1) commits to a number of cells; (2) gives a reason"]
    # the list of criteria is not the student's answer: it neither counts nor scores
    assert notebooks.answer_text(cell) == ""
    cell["source"] = source.replace(notebooks.ANSWER_PLACEHOLDER, "Few words.")
    assert notebooks.answer_text(cell) == "Few words."
    free = notebooks.cell_source(notebooks.read_notebook(path)["cells"][3])
    assert notebooks.RUBRIC_PREFIX not in free  # no rubric, no list


def test_release_check_sees_a_changed_rubric(tmp_path):
    notebooks.write_notebook(demo_notebook(NOTE), tmp_path / "solutions" / f"{STEM}.ipynb")
    notebooks.release(tmp_path / "solutions", tmp_path / "lessons")
    changed = [RUBRIC[0], {"criterion": "names a cause", "patterns": [r"\bbecause\b"]}]
    notebooks.write_notebook(demo_notebook(NOTE, changed),
                             tmp_path / "solutions" / f"{STEM}.ipynb")
    assert notebooks.release(tmp_path / "solutions", tmp_path / "lessons", check=True) == [
        f"{STEM}.ipynb: differs from `dlo-course course release`"]


# ------------------------------------------------------------------ the course's rubrics


def test_every_rubric_of_the_course_is_valid_and_met_by_its_solution():
    """The solutions' notes meet their own rubric's patterns (so the reviewer's hint for a
    right answer finds every criterion)."""
    for path in notebooks.notebooks_in(notebooks.SOLUTIONS_DIR):
        for name, info in notebooks.written_answers(path).items():
            met = notebooks.rubric_met(info["text"], info["rubric"])
            unmet = [item["criterion"] for item, ok in zip(info["rubric"], met) if not ok]
            assert not unmet, f"{path.name}: the solution's {name} does not meet {unmet}"


# ------------------------------------------------------------------ the instructor's reports


def class_of_four(tmp_path):
    """A catalog (the demo and a notebook no one hands in) and four students: alice writes the
    solution's note, bob issue 51's vacuous sentence, carol hands in nothing, dave too short."""
    catalog = tmp_path / "catalog"
    notebooks.write_notebook(demo_notebook(NOTE), catalog / f"{STEM}.ipynb")
    other = {**demo_notebook(NOTE), "cells": [answer_cell("prediction_other", 1, 5, NOTE, RUBRIC)]}
    notebooks.write_notebook(other, catalog / "97_not_handed_in.ipynb")  # no one grades it
    submissions = tmp_path / "submissions"
    notebooks.write_notebook(demo_notebook(NOTE), submissions / "alice" / f"{STEM}.ipynb")
    notebooks.write_notebook(demo_notebook(VACUOUS), submissions / "bob" / f"{STEM}.ipynb")
    (submissions / "carol").mkdir()  # hands in nothing
    notebooks.write_notebook(demo_notebook("Six, because."), submissions / "dave" / f"{STEM}.ipynb")
    return catalog, submissions


def read_class(out):
    with out.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        return reader.fieldnames, {row["student"]: row for row in reader}


def test_the_class_csv_and_the_feedback_sheets_show_what_awaits_review(tmp_path):
    catalog, submissions = class_of_four(tmp_path)
    out = tmp_path / "grades.csv"
    grade(submissions, out, grading_folder(tmp_path), catalog=catalog, progress=False)
    fieldnames, rows = read_class(out)
    assert fieldnames == [
        "student", "prediction_other", "prediction_cells", "analysis_free", "total",
        "max_total", "pending", "awaiting_review", "error", "prediction_other_text",
        "prediction_other_rubric", "prediction_cells_text", "prediction_cells_rubric",
        "analysis_free_text", "analysis_free_rubric"]
    alice, bob, carol, dave = (rows[name] for name in ("alice", "bob", "carol", "dave"))
    for row in (alice, bob):  # a right answer and a vacuous one: both for the instructor
        assert row["prediction_cells"] == row["analysis_free"] == PENDING
        assert float(row["total"]) == 0 and float(row["pending"]) == 3
        assert row["awaiting_review"] == "prediction_cells analysis_free"
        assert float(row["max_total"]) == 4 and float(row["prediction_other"]) == 0
    assert alice["prediction_cells_text"] == NOTE and bob["prediction_cells_text"] == VACUOUS
    assert alice["prediction_cells_rubric"] == "hint, not points: patterns of 2/2 criteria found"
    assert bob["prediction_cells_rubric"] == ("hint, not points: patterns of 1/2 criteria "
                                              "found; none for: gives a reason")
    assert alice["analysis_free_rubric"] == ""  # no rubric
    assert float(carol["total"]) == float(carol["pending"]) == 0
    assert carol["awaiting_review"] == "" and carol["prediction_cells_rubric"] == ""
    assert float(dave["prediction_cells"]) == 0  # too short: no points, nothing to review
    assert dave["analysis_free"] == PENDING and dave["awaiting_review"] == "analysis_free"

    sheets = tmp_path / "grades_feedback"
    sheet = (sheets / "bob.md").read_text()
    assert "**Total: 0 / 4 points.** 3 more await your instructor's review" in sheet
    assert (f"| {STEM} | `prediction_cells` | pending / 2 | awaiting the instructor's review "
            "(written answer, 16 words) |") in sheet
    assert ("- `prediction_cells` (98_rubric_demo), pending / 2:\n"
            "  - commits to a number of cells\n  - gives a reason") in sheet
    assert "### `prediction_cells`" not in sheet  # not failed: nothing to look at
    assert "- `analysis_free` (" not in sheet  # no rubric, no comment yet: nothing to list
    assert "| 97_not_handed_in | `prediction_other` | 0 / 1 | not graded |" in sheet
    assert "- `prediction_other` (" not in sheet  # not graded: no answer to review
    assert "Failed: " not in sheet and "conftest.py" not in sheet
    short = (sheets / "dave.md").read_text()
    assert "| `prediction_cells` | 0 / 2 | failed (written answer, 2 words) |" in short
    assert "2 words: this answer needs at least 10 words" in short

    # the file to fill in: every written answer graded, the text beside it, no points yet
    with (tmp_path / "grades_reviews.csv").open(newline="", encoding="utf-8") as f:
        to_review = list(csv.DictReader(f))
    assert [(r["student"], r["exercise"], r["points"], r["max_points"]) for r in to_review] == [
        ("alice", "prediction_cells", "", "2"), ("alice", "analysis_free", "", "1"),
        ("bob", "prediction_cells", "", "2"), ("bob", "analysis_free", "", "1"),
        ("dave", "prediction_cells", "", "2"), ("dave", "analysis_free", "", "1")]
    assert to_review[2]["text"] == VACUOUS


def test_the_instructors_reviews_give_the_points(tmp_path):
    catalog, submissions = class_of_four(tmp_path)
    out, to_review = tmp_path / "grades.csv", tmp_path / "grades_reviews.csv"
    grader = grading_folder(tmp_path)
    grade(submissions, out, grader, catalog=catalog, progress=False)
    with to_review.open(newline="", encoding="utf-8") as f:
        filled = list(csv.DictReader(f))
    given = {("alice", "prediction_cells"): ("2", "Right, and the reason is the threshold."),
             ("bob", "prediction_cells"): ("0", "A prediction commits to an outcome."),
             ("dave", "prediction_cells"): ("1", "Short, but right.")}
    for row in filled:
        row["points"], row["comment"] = given.get((row["student"], row["exercise"]), ("", ""))
    with to_review.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(filled[0]))
        writer.writeheader()
        writer.writerows(filled)
    grade(submissions, out, grader, catalog=catalog, progress=False, reviews=to_review)
    _, rows = read_class(out)
    alice, bob, dave = rows["alice"], rows["bob"], rows["dave"]
    assert (float(alice["prediction_cells"]), float(alice["total"]), float(alice["pending"])) \
        == (2, 2, 1)
    assert alice["awaiting_review"] == "analysis_free"
    assert (float(bob["prediction_cells"]), float(bob["total"]), float(bob["pending"])) \
        == (0, 0, 1)
    assert float(dave["prediction_cells"]) == float(dave["total"]) == 1  # the review wins
    sheet = (tmp_path / "grades_feedback" / "bob.md").read_text()
    assert "| `prediction_cells` | 0 / 2 | reviewed by the instructor (written answer" in sheet
    assert "  - Your instructor: A prediction commits to an outcome." in sheet
    assert "### `prediction_cells` (98_rubric_demo): 0 / 2" in sheet
    good = (tmp_path / "grades_feedback" / "alice.md").read_text()
    assert "**Total: 2 / 4 points.** 1 more await" in good
    # written again with the points given: the same file can go round once more
    with to_review.open(newline="", encoding="utf-8") as f:
        again = {(r["student"], r["exercise"]): (r["points"], r["comment"])
                 for r in csv.DictReader(f) if r["points"]}
    assert again == given


@pytest.mark.parametrize("rows, message", [
    ("student,exercise\nalice,prediction_cells\n", "needs the columns student, exercise and"),
    ("student,exercise,points\nalice,prediction_cells,two\n", "line 2: points must be a number"),
    ("student,exercise,points\nalice,prediction_cells,-1\n", "points must be a number from 0"),
    ("student,exercise,points\nalice,prediction_cells,3\n", "worth 2 points (got 3)"),
    ("student,exercise,points\nalicia,prediction_cells,1\n", "no student 'alicia' is graded"),
    ("student,exercise,points\nalice,RingBuffer,1\n", "'RingBuffer' is not a written answer"),
    ("student,exercise,points\nalice,prediction_cells,1\nalice,prediction_cells,2\n",
     "line 3: alice's 'prediction_cells' is reviewed twice"),
])
def test_a_wrong_reviews_file_is_refused_before_grading(tmp_path, rows, message):
    path = tmp_path / "reviews.csv"
    path.write_text(rows, encoding="utf-8")
    with pytest.raises(ValueError, match=re.escape(message)):
        read_reviews(path, ["alice", "bob"], {"prediction_cells": 2, "analysis_free": 1})
    (tmp_path / "class" / "alice").mkdir(parents=True)  # against the course's catalog
    result = CliRunner().invoke(main, ["course", "grade", str(tmp_path / "class"), "--out",
                                       str(tmp_path / "g.csv"), "--reviews", str(path)])
    assert result.exit_code != 0 and "reviews.csv" in result.output  # nothing graded


def test_an_empty_points_cell_is_not_reviewed_yet(tmp_path):
    path = tmp_path / "reviews.csv"
    path.write_text("student,exercise,points,comment\nalice,prediction_cells,,later\n"
                    "bob,prediction_cells,1.5,\n", encoding="utf-8")
    assert read_reviews(path) == {("bob", "prediction_cells"): {"points": 1.5, "comment": ""}}


def test_the_rubrics_command_prints_every_rubric(tmp_path):
    notebooks.write_notebook(demo_notebook(NOTE), tmp_path / f"{STEM}.ipynb")
    result = CliRunner().invoke(main, ["course", "rubrics", "--solutions", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert result.output.split("\n")[4:11] == [
        f"## {STEM}", "",
        "- `prediction_cells`: 2 points, at least 10 words, reviewed by the instructor",
        r"  1. commits to a number of cells (any of: `\d`, `\bnone\b`)",
        r"  2. gives a reason (any of: `\bbecause\b`, `\bsince\b`)",
        "- `analysis_free`: 1 point, at least 10 words, reviewed by the instructor; no rubric",
        ""]
    bad = [{"criterion": "gives a reason", "patterns": ["(because"]}]
    notebooks.write_notebook(demo_notebook(NOTE, bad), tmp_path / f"{STEM}.ipynb")
    result = CliRunner().invoke(main, ["course", "rubrics", "--solutions", str(tmp_path)])
    assert result.exit_code != 0
    assert f"{STEM}.ipynb: written answer 'prediction_cells'" in result.output


def test_the_course_rubrics_command_lists_every_written_answer():
    result = CliRunner().invoke(main, ["course", "rubrics"])
    assert result.exit_code == 0, result.output
    for e in notebooks.exercises(notebooks.SOLUTIONS_DIR):
        if e["kind"] == "text":
            assert f"- `{e['exercise']}`: {e['points']} point" in result.output


def grade_course_answer(tmp_path, stem: str, name: str, text: str, min_words=None) -> dict:
    """The course's grader on the solution notebook ``stem`` whose written answer ``name``
    holds ``text`` (and, if given, claims ``min_words`` in its metadata): that answer's
    grade."""
    nb = notebooks.read_notebook(notebooks.SOLUTIONS_DIR / f"{stem}.ipynb")
    cell = next(c for c in nb["cells"]
                if (notebooks.answer_info(c) or {}).get("exercise") == name)
    first = notebooks.cell_source(cell).split("\n", 1)[0]
    if min_words is not None:
        cell["metadata"]["dlo_course"]["min_words"] = min_words
        first = f"<!-- answer: {name} (1 point, at least {min_words} words) -->"
    cell["source"] = [first + "\n", text]
    student = tmp_path / "student"
    notebooks.write_notebook(nb, student / f"{stem}.ipynb")
    out = tmp_path / "grades.json"
    command = grading_command(student, notebooks.GRADING_TESTS_DIR, out) + ["-k", name]
    proc = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert out.is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    return {e["exercise"]: e for e in json.loads(out.read_text())["exercises"]}[name]


def test_issue_51s_vacuous_answer_earns_no_point_in_lesson_01(tmp_path):
    entry = grade_course_answer(tmp_path, "01_rl_and_the_bellman_equation",
                                "prediction_sweeps", VACUOUS)
    assert (entry["earned"], entry["pending"], entry["outcome"]) == (0, 1, "awaiting review")
    assert entry["text"] == VACUOUS
    assert all(item["patterns_found"] for item in entry["rubric"])  # what once gave 1/1


def test_a_student_cannot_lower_the_least_number_of_words(tmp_path):
    # The course's notebook sets the rule: a student's cell that asks for one word is graded
    # against the solution's 10: no points, and nothing to review.
    entry = grade_course_answer(tmp_path, "01_rl_and_the_bellman_equation",
                                "prediction_sweeps", "5, because the mask.", min_words=1)
    assert entry["earned"] == 0 and "at least 10 words" in entry["message"]
    assert "pending" not in entry


# ------------------------------------------------------------------ lessons 10 to 13 (issue 38)
# The patterns earn nothing (issue 51), but the class CSV shows them to the reviewer as a
# hint, which should point at what is missing: each criterion's patterns name the concept
# the answer must contain. Below, for each written answer of lessons 10-13, wrong answers long
# enough to be read (each with a count or an outcome, and "because", "so" or "which") whose
# hint must show a criterion not found, and short right answers in which every criterion's
# patterns are found. The rubrics are read from the solutions' metadata, as the grader reads
# them.

WRONG_ANSWERS = {
 "prediction_verdicts": [
   "I think about three of them, because the robot is quite good and I like how it moves, so it should do fine overall.",
   "Our agent is significantly below the paper in most cells because the paper is better, as it was published in a good conference so it must be right.",
   "I predict that the robot will be better than the paper because the deep learning is powerful and modern, which is why it should win.",
 ],
 "prediction_seeds": [
   "The intervals will overlap because DDPG and TD3 are both good algorithms, so neither is better, which I think is the usual outcome.",
   "TD3 will be higher, since it is newer and newer methods are better; I am confident about this result in the end.",
   "They will be apart because the computer is fast and the pendulum is a simple task which any method solves quickly.",
 ],
 "prediction_successes": [
   "About ten percent of them, because relabelling is good and the agent learns faster which helps the training a lot overall.",
   "Most of the copies will succeed because hindsight experience replay is a powerful method that always works in practice.",
   "I think the relabelled copies succeed since the robot is well trained and the simulation is accurate, so it works well.",
 ],
 "prediction_cells": [
   "I think the answer is that most results are fine because the robot is good and deep learning works, so things go well.",
   "Twelve, because the method is powerful and I think it is a good guess, as most things go right about half the time.",
   "The paper will win because it is a published paper and the authors know what they are doing, so we will lose.",
 ],
 "prediction_factor": [
   "The number of nodes matters most because it is the most important thing in general, as everyone knows about that.",
   "I think the threshold is the main factor since it seems to me like the most important factor among the four listed here.",
   "The robot will do badly because deep reinforcement learning is hard and the simulation is slow, which makes everything harder.",
 ],
 "analysis_comparison": [
   ("Our agents are good and the paper's agents are also good. The comparison shows that both work well and that deep "
    "reinforcement learning is a powerful method for deformable objects. I think the results are convincing and the "
    "reproduction is successful overall, because the numbers look similar and the plots look nice. The robot moves the "
    "rod well in most cases and sometimes fails, which is normal for learning methods in robotics today."),
   ("The shipped agents do worse than the paper. The paper is better because they trained more and had more computers. "
    "We used fewer computers so our results are lower in general and the paper wins in most of the table, which is what "
    "I expected from the beginning. This is a common result in reproductions and it does not surprise me much at all "
    "since the authors had much more time and effort to put into their method."),
 ],
 "analysis_next_step": [
   ("I would change the reward function to be more interesting because it would make the robot smarter and better at the "
    "task, which is what we want in the end, so that is my proposal for the next step of this work."),
   ("The next step is to use a bigger neural network with more layers and a different activation function because deep "
    "learning always improves with bigger models, so the robot would become much better at shaping the rod."),
 ],
}
RIGHT_ANSWERS = {
 "prediction_verdicts": ["Two cells, because with 100 episodes the intervals are about ten points wide and the paper is near 100% in the easy cells."],
 "prediction_seeds": ["They will overlap: with only three seeds the t-quantile is 4.3, so the intervals are very wide."],
 "prediction_successes": ["About 30% of the copies, since the t' = t copies always succeed and the rod moves little between steps."],
 "prediction_cells": ["18 of the 24 cells, because 100 episodes give wide intervals and the paper is low at 0.03 m."],
 "prediction_factor": ["The database, because the large box holds goals outside the training box, which our short training never saw."],
 "analysis_comparison": [("The shipped recipe agents, evaluated on the paper's test goals with 100 episodes per cell, are not "
    "significantly worse than the paper in 19 of 24 cells. Their intervals are about ten points wide, so within does not "
    "mean equal. They fall short on the large database at 0.05 m with reinitialisation, goals outside the training box, "
    "while at 0.03 m they are often above the paper's own low numbers. My own 2-node agent reached 40% over 20 episodes.")],
 "analysis_next_step": [("Train the 4-node agent longer, with more transitions on more ranks, because the large database cells "
    "are still short of the paper and the current budget is a few per cent of the paper's; then evaluate 1000 episodes.")],
}

RUBRIC_LESSONS = {"prediction_verdicts": "10_generalisation",
                  "prediction_seeds": "11_reproducibility",
                  "prediction_successes": "12_hindsight_relabelling",
                  "prediction_cells": "13_capstone_table_one",
                  "prediction_factor": "13_capstone_table_one",
                  "analysis_comparison": "13_capstone_table_one",
                  "analysis_next_step": "13_capstone_table_one"}


def course_answer(name):
    stem = RUBRIC_LESSONS[name]
    return notebooks.written_answers(notebooks.SOLUTIONS_DIR / f"{stem}.ipynb")[name]


def test_every_written_answer_of_lessons_10_to_13_has_wrong_answers_here():
    for stem in sorted(set(RUBRIC_LESSONS.values())):
        names = set(notebooks.written_answers(notebooks.SOLUTIONS_DIR / f"{stem}.ipynb"))
        assert names <= set(WRONG_ANSWERS) and names <= set(RIGHT_ANSWERS), (stem, names)


@pytest.mark.parametrize("name, answer", [(n, a) for n, answers in WRONG_ANSWERS.items()
                                          for a in answers],
                         ids=[f"{n}-{i}" for n, answers in WRONG_ANSWERS.items()
                              for i in range(len(answers))])
def test_the_hint_of_a_long_wrong_answer_shows_a_criterion_not_found(name, answer):
    info = course_answer(name)
    assert len(answer.split()) >= info["min_words"], "the wrong answer must be long enough"
    met = notebooks.rubric_met(answer, info["rubric"])
    assert not all(met), f"{name}: a wrong answer meets every criterion: {answer!r}"


@pytest.mark.parametrize("name, answer", [(n, a) for n, answers in RIGHT_ANSWERS.items()
                                          for a in answers],
                         ids=list(RIGHT_ANSWERS))
def test_the_hint_of_a_right_answer_in_other_words_finds_every_criterion(name, answer):
    info = course_answer(name)
    assert len(answer.split()) >= info["min_words"]
    met = notebooks.rubric_met(answer, info["rubric"])
    unmet = [item["criterion"] for item, ok in zip(info["rubric"], met) if not ok]
    assert not unmet, f"{name}: {unmet}"
