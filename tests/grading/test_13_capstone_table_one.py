"""Grading: lesson 13, the capstone on Table I (the student's own agent: dlo_course.submission;
the verdict on each cell is lesson 10's ``table_verdict``, graded there).

``own_agent_report`` reads the folder handed in beside the notebook
(``13_submission/``: an actor file and the report of the graded protocol), evaluates that
actor again in a sandbox worker that runs none of the student's code, and gives the points
only if the report says what the actor does (:func:`dlo_course.submission.report_problems`).
The written answers (Markdown cells) are never run: they score for presence, length and
their rubric, and their text goes to the instructor.

The probes below run in the grading sandbox, the checks here.
"""

import pytest

pytestmark = pytest.mark.notebook("13_capstone_table_one")


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
