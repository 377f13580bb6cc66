"""Grading: lesson 13, the capstone on Table I (reference: dlo_course.reproduce.verdict; the
student's own agent: dlo_course.submission).

``count_not_worse`` is compared with a count made here from the library's verdicts (the
interval from the notebook's setup cell, the library's Wilson interval in percent), on rows
where counting the wrong verdicts, or leaving the interval's ends out of it, gives another
number. ``own_agent_report`` reads the folder handed in beside the notebook
(``13_submission/``: an actor file and the report of the graded protocol), evaluates that
actor again in a sandbox worker that runs none of the student's code, and gives the points
only if the report says what the actor does (:func:`dlo_course.submission.report_problems`).
The written answers (Markdown cells) are never run: they score for presence, length and
their rubric, and their text goes to the instructor.

The probes below run in the grading sandbox, the checks here.
"""

import pytest

from dlo_course.evaluation import wilson_interval
from dlo_course.reproduce import verdict

pytestmark = pytest.mark.notebook("13_capstone_table_one")


def library_interval(done_percent, episodes, z=1.959964):
    successes = round(done_percent * episodes / 100)
    return tuple(100 * x for x in wilson_interval(successes, episodes, z=z))


def count_rows():
    """Table-like rows with 4 verdicts "above", 5 "within" (2 of them on an end of the
    interval) and 6 "below"."""
    rows = []
    for p, n, paper in [(100.0, 100, 90.0), (87.0, 100, 73.4), (40.0, 20, 10.0),
                        (100.0, 1000, 99.0),                                  # above
                        (100.0, 100, 99.5), (81.0, 100, 80.2), (5.0, 20, 21.1),
                        (0.0, 20, 0.0), (100.0, 20, 100.0),                   # within
                        (87.0, 100, 99.8), (57.0, 100, 88.7), (40.0, 20, 99.5),
                        (0.0, 20, 73.4), (10.0, 20, 46.8), (35.0, 20, 99.8)]:  # below
        rows.append({"done_percent": p, "episodes": n, "paper_done_percent": paper})
    return rows


def check_verdicts(rows):
    """The library's verdict of each row, its interval computed from done % and episodes."""
    found = []
    for row in rows:
        low, high = library_interval(row["done_percent"], row["episodes"])
        found.append(verdict({"done_ci_low": low, "done_ci_high": high},
                             row["paper_done_percent"]))
    return found


def probe_count_not_worse(fn, rows):
    everything = fn([dict(row) for row in rows])
    every_other = fn([dict(row) for row in rows[::2]])
    nothing = fn([])
    return [int(everything), int(every_other), int(nothing)]


@pytest.mark.exercise("count_not_worse", points=3, reference="dlo_course.reproduce.verdict")
def test_count_not_worse(student):
    rows = count_rows()
    found = check_verdicts(rows)
    assert [found.count(v) for v in ("above", "within", "below")] == [4, 5, 6]  # the test's data
    want = [sum(v != "below" for v in check_verdicts(subset)) for subset in (rows, rows[::2])]
    got = student.run(probe_count_not_worse, rows)
    assert got == want + [0], (f"counts {got} for the rows, every other row and no row; "
                               f"expected {want + [0]}: count the verdicts \"above\" and "
                               f"\"within\"")


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_cells", points=1)
def test_prediction_cells(written_answer):
    written_answer.check()


@pytest.mark.exercise("prediction_factor", points=1)
def test_prediction_factor(written_answer):
    written_answer.check()


@pytest.mark.exercise("analysis_comparison", points=2)
def test_analysis_comparison(written_answer):
    written_answer.check()


@pytest.mark.exercise("analysis_next_step", points=1)
def test_analysis_next_step(written_answer):
    written_answer.check()


# ------------------------------------------------------------------ the student's own agent

# One evaluation of the graded protocol: about 8 s of CPU for an actor that never reaches a
# goal (every episode runs all its actions), several times that on a busy machine; its own
# limit, whatever DLO_COURSE_GRADING_TIMEOUT gives an exercise.
REEVALUATION_TIMEOUT = 150.0


def probe_behaviour(_, actor_bytes):
    """In a sandbox worker that runs none of the student's code: the handed-in actor file's
    node count and actions on the probe observations (no simulation)."""
    from pathlib import Path

    from dlo_course.submission import actor_behaviour

    path = Path("handed_in_actor.pt")  # in the worker's scratch folder
    path.write_bytes(actor_bytes)
    return actor_behaviour(path)


def probe_reevaluate(_, actor_bytes):
    """In a sandbox worker that runs none of the student's code: the handed-in actor file
    (loaded with weights_only=True) on the graded protocol, as the library measures it."""
    from pathlib import Path

    from dlo_course.submission import evaluate_graded

    path = Path("handed_in_actor.pt")  # in the worker's scratch folder
    path.write_bytes(actor_bytes)
    return evaluate_graded(path)


def shipped_actor_digests():
    from dlo_course.submission import sha256_of, shipped_actor_files

    return tuple(sha256_of(p) for p in shipped_actor_files())


@pytest.mark.timeout(REEVALUATION_TIMEOUT + 240)
@pytest.mark.exercise("own_agent_report", points=2)
def test_own_agent_report(notebook_folder, data_probe, grade_record):
    """The points reward an agent the student trained in lesson 9, as the grader measures
    it: 2 nodes and behaving like no shipped actor
    (:func:`dlo_course.submission.likeness_problems`, checked first: no simulation), above
    the learning floor (:func:`dlo_course.submission.floor_problems`), with a report that
    says what it does (:func:`dlo_course.submission.report_problems`). What the grader
    measured goes into the grades, for the class CSV and the leaderboard."""
    from dlo_course.submission import (SUBMISSION_DIR, SubmissionError, floor_problems,
                                       likeness_problems, measured_fields, read_submission,
                                       report_problems)

    try:
        report, actor_bytes = read_submission(notebook_folder / SUBMISSION_DIR)
    except SubmissionError as err:
        pytest.fail(f"own_agent_report: {err}", pytrace=False)
    forbidden = shipped_actor_digests()
    problems = report_problems(report, actor_bytes, None, forbidden)  # before any simulation
    if not problems:
        problems = likeness_problems(data_probe(probe_behaviour, actor_bytes))
    if not problems:
        measured = data_probe(probe_reevaluate, actor_bytes, timeout=REEVALUATION_TIMEOUT)
        problems = report_problems(report, actor_bytes, measured, forbidden)
        grade_record["measured"] = measured_fields(measured, report_matches=not problems)
        problems += floor_problems(measured)
    assert not problems, ("own_agent_report: no points for the handed-in agent:\n- "
                          + "\n- ".join(problems))
