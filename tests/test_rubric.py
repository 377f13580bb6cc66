"""Rubrics of written answers (issue 30): reading and checking them, scoring an answer by the
share of its criteria met, releasing them to the student, and reporting them to the
instructor (feedback sheets, the class CSV, ``dlo-course course rubrics``).

Everything runs on small real notebooks written to ``tmp_path``, graded by the real grader:
a copy of ``tests/grading/conftest.py`` beside a small grading test file.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess

import pytest
from click.testing import CliRunner

from dlo_course.cli import main
from dlo_course.grading import notebooks
from dlo_course.grading.grade import grade, grading_command
from dlo_course.paths import REPO_ROOT

STEM = "98_rubric_demo"  # not a course notebook: the grader falls back to the cell's rubric
RUBRIC = [{"criterion": "commits to a number of cells", "patterns": [r"\d", r"\bnone\b"]},
          {"criterion": "gives a reason", "patterns": [r"\bbecause\b", r"\bsince\b"]}]
NOTE = ("A good answer names a number of cells, for instance 6, and says why, because the "
        "threshold is tight.")
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


def test_score_is_the_share_of_criteria_met():
    rubric = notebooks.check_rubric(RUBRIC, "prediction_cells")
    both = "I expect 6 cells to pass, because the threshold is tight for the six-node rod."
    one = "I expect most of the cells to pass, because the threshold is tight for this rod."
    neither = "I expect most of the cells to pass; the threshold looks generous to me here."
    assert notebooks.written_answer_score(both, 10, rubric) == 1
    assert notebooks.written_answer_score(one, 10, rubric) == 0.5
    assert notebooks.written_answer_score(neither, 10, rubric) == 0
    assert notebooks.written_answer_score(neither, 10, None) == 1  # no rubric: length only
    # every keyword, too short: nothing
    assert notebooks.written_answer_score("6 because.", 10, rubric) == 0
    assert notebooks.written_answer_score("", 10, rubric) == 0
    assert notebooks.rubric_met("NONE, SINCE it fails", rubric) == [True, True]  # any case


def test_the_grader_gives_partial_points_and_records_the_criteria(tmp_path):
    one = "I expect most of the cells to pass, because the threshold is tight for this rod."
    graded = grade_one(tmp_path, demo_notebook(one))
    cells, free = graded["prediction_cells"], graded["analysis_free"]
    assert (cells["earned"], cells["points"], cells["outcome"]) == (1, 2, "partly met")
    assert cells["rubric"] == [{"criterion": "commits to a number of cells", "met": False},
                               {"criterion": "gives a reason", "met": True}]
    assert "1 of 2 criteria met" in cells["message"]
    assert "(1) commits to a number of cells" in cells["message"]
    assert (free["earned"], free["outcome"]) == (1, "passed") and "rubric" not in free


@pytest.mark.parametrize("answer, earned", [
    ("I expect 6 cells to pass, because the threshold is tight for the six-node rod.", 2),
    ("I expect most of the cells to pass; the threshold looks generous to me here.", 0),
    ("6 cells, because tight.", 0),  # every criterion met, but too short
])
def test_the_grader_scores_met_and_unmet_and_short_answers(tmp_path, answer, earned):
    graded = grade_one(tmp_path, demo_notebook(answer))
    assert graded["prediction_cells"]["earned"] == earned
    assert graded["prediction_cells"]["outcome"] == ("passed" if earned else "failed")


def test_the_grader_reports_a_malformed_rubric(tmp_path):
    bad = [{"criterion": "gives a reason", "patterns": ["(because"]}]
    graded = grade_one(tmp_path, demo_notebook(NOTE, bad))
    entry = graded["prediction_cells"]
    assert entry["earned"] == 0
    assert f"{STEM}.ipynb" in entry["message"] and "'prediction_cells'" in entry["message"]
    assert "not a valid regular expression" in entry["message"]


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
    """The solutions' notes meet their own rubric (so the grader gives them full points)."""
    for path in notebooks.notebooks_in(notebooks.SOLUTIONS_DIR):
        for name, info in notebooks.written_answers(path).items():
            met = notebooks.rubric_met(info["text"], info["rubric"])
            unmet = [item["criterion"] for item, ok in zip(info["rubric"], met) if not ok]
            assert not unmet, f"{path.name}: the solution's {name} does not meet {unmet}"


# ------------------------------------------------------------------ the instructor's reports


def test_feedback_sheets_and_the_class_csv_show_the_criteria(tmp_path):
    catalog = tmp_path / "catalog"
    notebooks.write_notebook(demo_notebook(NOTE), catalog / f"{STEM}.ipynb")
    other = {**demo_notebook(NOTE), "cells": [answer_cell("prediction_other", 1, 5, NOTE, RUBRIC)]}
    notebooks.write_notebook(other, catalog / "97_not_handed_in.ipynb")  # no one grades it
    one = "I expect most of the cells to pass, because the threshold is tight for this rod."
    submissions = tmp_path / "submissions"
    notebooks.write_notebook(demo_notebook(NOTE), submissions / "alice" / f"{STEM}.ipynb")
    notebooks.write_notebook(demo_notebook(one), submissions / "bob" / f"{STEM}.ipynb")
    (submissions / "carol").mkdir()  # hands in nothing
    out = tmp_path / "grades.csv"
    grade(submissions, out, grading_folder(tmp_path), catalog=catalog, progress=False)
    with out.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == [
            "student", "prediction_other", "prediction_cells", "analysis_free", "total",
            "max_total", "error", "prediction_other_text", "prediction_other_rubric",
            "prediction_cells_text", "prediction_cells_rubric", "analysis_free_text",
            "analysis_free_rubric"]
        rows = {row["student"]: row for row in reader}
    alice, bob, carol = rows["alice"], rows["bob"], rows["carol"]
    assert alice["prediction_cells_rubric"] == "2/2 met" and float(alice["total"]) == 3
    assert bob["prediction_cells_rubric"] == "1/2 met; missing: commits to a number of cells"
    assert float(bob["prediction_cells"]) == 1 and float(bob["total"]) == 2
    assert bob["prediction_cells_text"] == one
    assert alice["analysis_free_rubric"] == bob["analysis_free_rubric"] == ""  # no rubric
    assert carol["prediction_cells_rubric"] == "" and float(carol["total"]) == 0
    assert alice["prediction_other_rubric"] == "" and float(alice["max_total"]) == 4

    sheets = tmp_path / "grades_feedback"
    sheet = (sheets / "bob.md").read_text()
    assert f"| {STEM} | `prediction_cells` | 1 / 2 | partly met (written answer, 16 words) |" \
        in sheet
    assert ("- `prediction_cells` (98_rubric_demo), 1 / 2:\n"
            "  - [ ] commits to a number of cells (not met)\n"
            "  - [x] gives a reason") in sheet
    assert "1 of 2 criteria met; your answer does not yet show: (1) commits to a number" in sheet
    assert "- `analysis_free` (" not in sheet  # no rubric, nothing to list
    assert "| 97_not_handed_in | `prediction_other` | 0 / 1 | not graded |" in sheet
    assert "- `prediction_other` (" not in sheet  # not graded: no criteria met or missed
    assert "Failed: " not in sheet and "conftest.py" not in sheet
    good = (sheets / "alice.md").read_text()
    assert "  - [x] commits to a number of cells\n  - [x] gives a reason" in good
    assert "Every check passed." not in good  # prediction_other was not handed in


def test_the_rubrics_command_prints_every_rubric(tmp_path):
    notebooks.write_notebook(demo_notebook(NOTE), tmp_path / f"{STEM}.ipynb")
    result = CliRunner().invoke(main, ["course", "rubrics", "--solutions", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert result.output.split("\n")[2:9] == [
        f"## {STEM}", "",
        "- `prediction_cells`: 2 points, at least 10 words",
        r"  1. commits to a number of cells (any of: `\d`, `\bnone\b`)",
        r"  2. gives a reason (any of: `\bbecause\b`, `\bsince\b`)",
        "- `analysis_free`: 1 point, at least 10 words; no rubric: all points if long enough",
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


def test_a_student_cannot_lower_the_least_number_of_words(tmp_path):
    # The course's notebook sets the rule: a student's cell that asks for one word is graded
    # against the solution's 10, and its criteria, all met here, do not save it.
    stem = "01_rl_and_the_bellman_equation"
    nb = notebooks.read_notebook(notebooks.SOLUTIONS_DIR / f"{stem}.ipynb")
    cell = next(c for c in nb["cells"] if (notebooks.answer_info(c) or {}).get("exercise")
                == "prediction_sweeps")
    cell["metadata"]["dlo_course"]["min_words"] = 1
    cell["source"] = ["<!-- answer: prediction_sweeps (1 point, at least 1 words) -->\n",
                      "5, because the mask."]
    student = tmp_path / "student"
    notebooks.write_notebook(nb, student / f"{stem}.ipynb")
    out = tmp_path / "grades.json"
    command = grading_command(student, notebooks.GRADING_TESTS_DIR, out) + ["-k", "prediction_sweeps"]
    proc = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert out.is_file(), proc.stdout[-3000:] + proc.stderr[-3000:]
    entry = {e["exercise"]: e for e in json.loads(out.read_text())["exercises"]}["prediction_sweeps"]
    assert entry["earned"] == 0 and "at least 10 words" in entry["message"]


# ------------------------------------------------------------------ lessons 10 to 13 (issue 38)
# Each criterion names the concept the answer must contain, so that a long answer without it
# loses the point: below, for each written answer of lessons 10-13, wrong answers long enough
# to count (each with a count or an outcome, and "because", "so" or "which" that the old
# patterns took for a reason) that must miss a criterion, and short right answers that must
# meet them all. The rubrics are read from the solutions' metadata, as the grader reads them.

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
def test_a_long_wrong_answer_loses_the_point(name, answer):
    info = course_answer(name)
    assert len(answer.split()) >= info["min_words"], "the wrong answer must be long enough"
    met = notebooks.rubric_met(answer, info["rubric"])
    assert not all(met), f"{name}: a wrong answer meets every criterion: {answer!r}"
    assert notebooks.written_answer_score(answer, info["min_words"], info["rubric"]) < 1


@pytest.mark.parametrize("name, answer", [(n, a) for n, answers in RIGHT_ANSWERS.items()
                                          for a in answers],
                         ids=list(RIGHT_ANSWERS))
def test_a_right_answer_in_other_words_meets_every_criterion(name, answer):
    info = course_answer(name)
    assert len(answer.split()) >= info["min_words"]
    met = notebooks.rubric_met(answer, info["rubric"])
    unmet = [item["criterion"] for item, ok in zip(info["rubric"], met) if not ok]
    assert not unmet, f"{name}: {unmet}"
