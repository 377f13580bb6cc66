"""Grading one folder of notebooks (a pytest run of ``tests/grading``) and a whole class
(``dlo-course course grade``: one CSV row per student, a log and a feedback sheet each).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterable

from dlo_course.grading.feedback import feedback_markdown, rubric_summary
from dlo_course.grading.notebooks import GRADING_TESTS_DIR, SOLUTIONS_DIR, exercises
from dlo_course.grading.reviews import apply_reviews, read_reviews, review_rows, write_review_file
from dlo_course.grading.runner import ExerciseError, find_notebook
from dlo_course.paths import REPO_ROOT
from dlo_course.submission import CSV_COLUMNS, SUBMISSION_DIR, csv_fields

OWN_AGENT_ITEM, OWN_AGENT_NOTEBOOK = "own_agent_report", "13_capstone_table_one"
PENDING = "pending"  # the class CSV's points of a written answer awaiting the instructor's review
SUMMARY_COLUMNS = ("total", "max_total", "pending", "awaiting_review", "error")


def grading_command(notebooks: str | Path, tests: str | Path = GRADING_TESTS_DIR,
                    json_out: str | Path | None = None, quiet: bool = True) -> list[str]:
    """The pytest command that grades the notebooks in ``notebooks``."""
    cmd = [sys.executable, "-m", "pytest", str(tests), "--notebooks", str(notebooks),
           "-p", "no:cacheprovider", "-o", "console_output_style=classic"]
    if json_out is not None:
        cmd += ["--grades-json", str(json_out)]
    if quiet:
        cmd.append("-q")
    return cmd


REFERENCE_CACHE_VARIABLE = "DLO_COURSE_REFERENCE_CACHE"
"""A folder where the grader keeps the references that need real MPI processes, shared by
the students of one ``course grade`` (``tests/grading/conftest.py``): the same for every
student, and each costs two MPI launches (about 10 s)."""


def grade_folder(notebooks: str | Path, tests: str | Path = GRADING_TESTS_DIR,
                 timeout: float = 1800, reference_cache: str | Path | None = None
                 ) -> dict[str, Any]:
    """Grade one folder of notebooks in a pytest subprocess.

    ``reference_cache``: a folder the graders of a class share for the references they
    compute in MPI processes (:data:`REFERENCE_CACHE_VARIABLE`); None: each computes its own.

    Returns:
        The grader's JSON report (``exercises``: notebook, exercise, points, earned, outcome,
        and for a written answer awaiting review its ``pending`` points; ``total``,
        ``max_total``), plus ``returncode``, ``output`` (pytest's text) and
        ``error`` (None, or why there is no report).
    """
    with tempfile.TemporaryDirectory() as tmp:
        report_path = Path(tmp) / "grades.json"
        env = dict(os.environ, MPLBACKEND="Agg", DLO_COURSE_FAST="1",
                   DLO_COURSE_OUTPUT=str(Path(tmp) / "output"))
        if reference_cache is not None:
            env[REFERENCE_CACHE_VARIABLE] = str(reference_cache)
        try:
            proc = subprocess.run(grading_command(notebooks, tests, report_path),
                                  capture_output=True, text=True, timeout=timeout,
                                  cwd=REPO_ROOT, env=env)
            output, returncode = proc.stdout + proc.stderr, proc.returncode
        except subprocess.TimeoutExpired as err:
            output, returncode = f"grading timed out after {timeout} s: {err}", -1
        if report_path.is_file():
            report = json.loads(report_path.read_text())
            report["error"] = None
        else:
            report = {"exercises": [], "total": 0, "max_total": 0,
                      "error": output.strip().splitlines()[-1] if output.strip() else "no report"}
    report.update(returncode=returncode, output=output)
    return report


def grade(submissions: str | Path, out: str | Path, tests: str | Path = GRADING_TESTS_DIR,
          timeout: float = 1800, catalog: str | Path = SOLUTIONS_DIR,
          progress: bool = True, jobs: int = 1,
          reviews: str | Path | None = None) -> list[dict[str, Any]]:
    """Grade every student folder in ``submissions`` and write one CSV row per student.

    Each sub-folder of ``submissions`` is one student (its name is the student's id) and holds
    that student's notebooks. Columns: ``student``, one column of points per exercise and
    written answer (in the order of the course; :data:`PENDING` for a written answer that
    awaits the instructor's review), ``total`` (the points given so far), ``max_total``,
    ``pending`` (the points of the written answers awaiting review), ``awaiting_review``
    (their names, separated by spaces), ``error`` (empty when grading ran), the student's own
    agent as handed in with lesson 13, when it is
    graded (:data:`dlo_course.submission.CSV_COLUMNS`: what the grader measured of the
    handed-in actor, whether the report says so, and what the report claims of its training
    run; empty when absent),
    then one column ``<answer>_text`` per written answer holding what the
    student wrote, verbatim, each followed by ``<answer>_rubric``: which criteria of its rubric
    have their patterns in the answer, a hint for the reviewer and never points
    (:func:`rubric_summary`; empty without a rubric).

    No pattern gives a written answer points (:mod:`dlo_course.grading.reviews`): the
    instructor's ``reviews`` file does, merged into the columns, the totals and the feedback
    sheets. ``<out stem>_reviews.csv`` beside the CSV lists every written answer to review,
    with the points already given: fill it in and pass it as ``reviews``.

    Beside the CSV: ``<out stem>_logs/<student>.txt``, the grader's full output, and
    ``<out stem>_feedback/<student>.md``, a feedback sheet for the student: the points of
    every exercise, the written answers awaiting review and, for each one that lost points,
    the failing check's message (:func:`feedback_markdown`).

    Args:
        catalog: folder whose notebooks list the exercises (the solutions), so every student
            gets every column even if their notebook is missing.
        jobs: students graded at the same time (each by its own processes).
        reviews: the instructor's points for written answers (a CSV: ``student``,
            ``exercise``, ``points``, optional ``comment``), checked before any grading.
    """
    submissions, out = Path(submissions), Path(out)
    students = sorted(p for p in submissions.iterdir() if p.is_dir() and not p.name.startswith("."))
    if not students:
        raise FileNotFoundError(f"no student folders in {submissions}")
    known = exercises(catalog) if Path(catalog).is_dir() else []
    written = {e["exercise"]: e["points"] for e in known  # prose: a choice is automatic
               if e.get("kind") == "text" and not e.get("choices")}
    reviewed = read_reviews(reviews, [p.name for p in students], written or None) \
        if reviews is not None else {}
    columns = [e["exercise"] for e in known]
    texts = [e["exercise"] for e in known if e.get("kind") == "text"]
    logs = out.parent / f"{out.stem}_logs"
    feedback = out.parent / f"{out.stem}_feedback"
    logs.mkdir(parents=True, exist_ok=True)
    feedback.mkdir(parents=True, exist_ok=True)
    from concurrent.futures import ThreadPoolExecutor, as_completed

    from tqdm.auto import tqdm

    # Threads are enough: each student is graded by its own processes, the threads only wait.
    reports: list[dict[str, Any]] = [{}] * len(students)
    with ThreadPoolExecutor(max_workers=max(1, int(jobs))) as pool, \
            tempfile.TemporaryDirectory(prefix="dlo-grading-references-") as shared, \
            tqdm(total=len(students), unit="student", desc="grading",
                 disable=not progress, file=sys.stderr) as bar:
        futures = {pool.submit(grade_folder, student, tests, timeout, shared): i
                   for i, student in enumerate(students)}
        for future in as_completed(futures):
            try:
                reports[futures[future]] = future.result()
            except Exception as err:  # noqa: BLE001 - one student's grading, not the class's
                reports[futures[future]] = _failed_report(err)
            bar.set_postfix(last=students[futures[future]].name)
            bar.update(1)
    rows, to_review = [], []
    for student, report in zip(students, reports):
        (logs / f"{student.name}.txt").write_text(str(report.get("output", "")),
                                                   encoding="utf-8", errors="replace")
        if not _well_formed(report):
            report = _failed_report(ValueError("the grader's report of this student is "
                                               "malformed"), report.get("output", ""))
        problems = [report["error"]] if report["error"] else []
        problems += [f"the review of {name} is not applied: the answer was not graded"
                     for name in apply_reviews(report, student.name, reviewed)]
        earned = {e["exercise"]: PENDING if e.get("pending") else e["earned"]
                  for e in report["exercises"]}
        awaiting = [e["exercise"] for e in report["exercises"] if e.get("pending")]
        columns += [name for name in earned if name not in columns]
        texts += [e["exercise"] for e in report["exercises"]
                  if "text" in e and e["exercise"] not in texts]
        max_total = sum(e["points"] for e in known) if known else report["max_total"]
        row = {"student": student.name, **earned, "total": report["total"],
               "max_total": max_total,
               "pending": sum(e.get("pending", 0) for e in report["exercises"]),
               "awaiting_review": " ".join(awaiting), "error": "; ".join(problems)}
        to_review += review_rows(student.name, report)
        row.update({f"{e['exercise']}_text": e["text"] for e in report["exercises"]
                    if "text" in e})
        row.update({f"{e['exercise']}_rubric": rubric_summary(e["rubric"])
                    for e in report["exercises"] if "rubric" in e})
        row.update(_own_agent_fields(student, report))
        rows.append(row)
        try:
            sheet = feedback_markdown(student.name, report, known, max_total)
        except Exception as err:  # noqa: BLE001 - the CSV row stands without its sheet
            sheet = f"# {student.name}\n\nThe feedback sheet could not be written ({err!r:.200}).\n"
        (feedback / f"{student.name}.md").write_text(sheet, encoding="utf-8", errors="replace")
    out.parent.mkdir(parents=True, exist_ok=True)
    text_columns = [f"{name}_{part}" for name in texts for part in ("text", "rubric")]
    own_columns = list(CSV_COLUMNS) if OWN_AGENT_ITEM in columns else []  # lesson 13 graded
    with out.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=["student", *columns, *SUMMARY_COLUMNS,
                                               *own_columns, *text_columns])
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, 0) for c in columns}
                            | {c: row.get(c, "") for c in text_columns}
                            | {k: row[k] for k in ("student", *SUMMARY_COLUMNS)}
                            | {c: row.get(c, "") for c in own_columns})
    write_review_file(out.parent / f"{out.stem}_reviews.csv", to_review)
    return rows


def _failed_report(err: BaseException, output: str = "") -> dict[str, Any]:
    """:func:`grade_folder`'s report of a student whose grading failed in the grader itself:
    no points, the error said."""
    return {"exercises": [], "total": 0, "max_total": 0, "returncode": -1,
            "error": f"grading failed: {type(err).__name__}: {str(err)[:300]}",
            "output": f"{output}\ngrading failed: {err!r:.2000}"}


def _well_formed(report: Any) -> bool:
    """Whether a grades report has the shape :func:`grade` reads (it comes from a pytest run
    whose notebooks and hand-ins are the student's)."""
    items = report.get("exercises") if isinstance(report, dict) else None
    return isinstance(items, list) and all(
        isinstance(e, dict) and isinstance(e.get("exercise"), str)
        and isinstance(e.get("earned"), (int, float)) and isinstance(e.get("points"), (int, float))
        and isinstance(e.get("pending", 0), (int, float))
        for e in items) and isinstance(report.get("total"), (int, float))


def _own_agent_fields(student: Path, report: dict[str, Any]) -> dict[str, Any]:
    """The class CSV's columns of a student's handed-in agent (:func:`csv_fields`): what the
    grader measured (recorded with ``own_agent_report``'s grade) and what the report claims.
    Never raises: whatever the student handed in, the class is graded to its end."""
    graded = [e for e in report.get("exercises", []) if e.get("exercise") == OWN_AGENT_ITEM]
    measured = graded[0].get("measured") if graded else None
    try:
        folder = find_notebook(student, OWN_AGENT_NOTEBOOK).parent / SUBMISSION_DIR
    except (ExerciseError, OSError):
        folder = None
    try:
        return csv_fields(folder, measured)
    except Exception:  # noqa: BLE001 - a hand-in must never stop a class's grading
        return csv_fields(None, measured)


LEADERBOARD_NOTE = (
    "Measured: by the grader, at grading time, with the handed-in actor on the graded protocol "
    "(done %, mean final distance) and without moving (doing nothing). Claimed: from the "
    "student's report.json, which nothing checks (the training run's transitions and "
    "episodes). Own agent: the 2 points of `own_agent_report` (a 2-node agent the student "
    "trained, above the learning floor, with a report that says what it does).")


def leaderboard_markdown(rows: Iterable[dict[str, Any]]) -> str:
    """The class's own agents as a Markdown table, from :func:`grade`'s rows: the agents that
    earned ``own_agent_report``'s points first, by the grader's measured done % on the graded
    protocol (best first), then mean distance; then the other agents the grader evaluated;
    then those it did not evaluate (nothing handed in, or refused before evaluation); ties by
    name. Measured and claimed numbers sit in columns of their own (:data:`LEADERBOARD_NOTE`)."""
    def number(value, default):
        return value if isinstance(value, (int, float)) and not isinstance(value, bool) \
            else default

    def accepted(row):
        points = row.get(OWN_AGENT_ITEM, 0)
        return number(points, 0) > 0 and row.get("measured_done_percent", "") != ""

    def key(row):
        rank = 0 if accepted(row) else 1 if row.get("measured_done_percent", "") != "" else 2
        return (rank, -number(row.get("measured_done_percent"), 0.0),
                number(row.get("measured_distance"), float("inf")), row["student"])

    def cell(value, fmt="g"):
        return "" if value in ("", None) else format(value, fmt) if not isinstance(
            value, str) else value

    lines = [LEADERBOARD_NOTE, "",
             "| # | student | own agent | done % (measured) | mean distance, m (measured) | "
             "doing nothing, m (measured) | report matches | done % (claimed) | transitions "
             "(claimed) | episodes (claimed) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for place, row in enumerate(sorted(rows, key=key), start=1):
        status = {1: "yes", 0: "no"}.get(row.get("report_verified"), "")
        lines.append(f"| {place} | {row['student']} | {'yes' if accepted(row) else 'no'} | "
                     f"{cell(row.get('measured_done_percent', ''))} | "
                     f"{cell(row.get('measured_distance', ''), '.3f')} | "
                     f"{cell(row.get('do_nothing_distance', ''), '.3f')} | {status} | "
                     f"{cell(row.get('claimed_done_percent', ''))} | "
                     f"{cell(row.get('claimed_run_transitions', ''))} | "
                     f"{cell(row.get('claimed_run_episodes', ''))} |")
    return "\n".join(lines) + "\n"


def summary_lines(items: Iterable[dict[str, Any]]) -> list[str]:
    """Human-readable points per exercise, grouped by notebook, and the total."""
    items = list(items)
    lines, current = [], None
    width = max([len(i["exercise"]) for i in items] + [8])
    for item in items:
        if item["notebook"] != current:
            current = item["notebook"]
            lines.append(current)
        mark = "ok" if item["earned"] == item["points"] else item["outcome"]
        lines.append(f"  {item['exercise']:<{width}} {item['earned']:>3g} / "
                     f"{item['points']:<3g} {mark}")
    total = sum(i["earned"] for i in items)
    max_total = sum(i["points"] for i in items)
    pending = sum(i.get("pending", 0) for i in items)
    lines.append(f"TOTAL {total:g} / {max_total:g} points" + (
        f" ({pending:g} points of written answers await the instructor's review)"
        if pending else ""))
    return lines
