"""Every lesson asks the student to predict before a cell shows the answer (project issue 30).

A predict-then-run check is a graded written answer named ``prediction_*`` whose question sits
in the Markdown just above it, and a code cell after it that runs what was predicted. Writing
the prediction first is what makes the run teach: the student sees what they expected.
"""

import re

import pytest

from dlo_course.grading.notebooks import (SOLUTIONS_DIR, answer_info, notebooks_in,
                                          read_notebook)

NOTEBOOKS = notebooks_in(SOLUTIONS_DIR)


def predict_then_run_checks(cells: list[dict]) -> list[str]:
    """Names of the ``prediction_*`` written answers that follow a Markdown cell asking to
    predict and are followed (possibly after other written answers) by a code cell."""
    found = []
    for i, cell in enumerate(cells):
        info = answer_info(cell)
        if info is None or not info["exercise"].startswith("prediction"):
            continue
        before = "".join(cells[i - 1].get("source", "")) if i > 0 else ""
        asks = cells[i - 1].get("cell_type") == "markdown" and re.search(r"(?i)\bpredict", before)
        rest = cells[i + 1:]
        runs = next((c for c in rest if answer_info(c) is None and c["cell_type"] == "code"), None)
        if asks and runs is not None:
            found.append(info["exercise"])
    return found


def test_the_course_has_its_lessons():
    assert len(NOTEBOOKS) >= 16


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_every_lesson_has_a_predict_then_run_check(path):
    checks = predict_then_run_checks(read_notebook(path)["cells"])
    assert checks, (f"{path.name}: no predict-then-run check (a Markdown question with "
                    f"'predict', then a written answer prediction_*, then the code cell that "
                    f"shows the answer)")


def test_a_prediction_without_a_question_or_a_run_is_not_a_check():
    question = {"cell_type": "markdown", "metadata": {}, "source": "### Predict, then run: how many?"}
    answer = {"cell_type": "markdown", "source": "<!-- answer: prediction_x (1 point) -->\n...",
              "metadata": {"dlo_course": {"answer": "prediction_x", "points": 1, "min_words": 5}}}
    run = {"cell_type": "code", "metadata": {}, "source": "print(3)", "outputs": [],
           "execution_count": None}
    assert predict_then_run_checks([question, answer, run]) == ["prediction_x"]
    assert predict_then_run_checks([answer, run]) == []  # no question before it
    assert predict_then_run_checks([question, answer]) == []  # nothing runs after it
    plain = {**question, "source": "Write what you think."}
    assert predict_then_run_checks([plain, answer, run]) == []
