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
from dlo_course.grading.runner import ExerciseError, find_notebook
from dlo_course.paths import REPO_ROOT
from dlo_course.submission import CSV_COLUMNS, SUBMISSION_DIR, csv_fields

OWN_AGENT_ITEM, OWN_AGENT_NOTEBOOK = "own_agent_report", "13_capstone_table_one"


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
        The grader's JSON report (``exercises``: notebook, exercise, points, earned, outcome;
        ``total``, ``max_total``), plus ``returncode``, ``output`` (pytest's text) and
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
          progress: bool = True, jobs: int = 1) -> list[dict[str, Any]]:
    """Grade every student folder in ``submissions`` and write one CSV row per student.

    Each sub-folder of ``submissions`` is one student (its name is the student's id) and holds
    that student's notebooks. Columns: ``student``, one column of points per exercise and
    written answer (in the order of the course), ``total``, ``max_total``, ``error`` (empty
    when grading ran), the student's own agent as handed in with lesson 13, when it is
    graded (:data:`dlo_course.submission.CSV_COLUMNS`: the done % its report claims, whether
    the grader's evaluation verified it, the run's transitions and episodes; empty when
    absent),
    then one column ``<answer>_text`` per written answer holding what the
    student wrote, verbatim, each followed by ``<answer>_rubric``: the criteria of its rubric
    met, e.g. ``1/2 met; missing: gives a reason`` (empty without a rubric).

    Beside the CSV: ``<out stem>_logs/<student>.txt``, the grader's full output, and
    ``<out stem>_feedback/<student>.md``, a feedback sheet for the student: the points of
    every exercise and, for each one that lost points, the failing check's message
    (:func:`feedback_markdown`).

    Args:
        catalog: folder whose notebooks list the exercises (the solutions), so every student
            gets every column even if their notebook is missing.
        jobs: students graded at the same time (each by its own processes).
    """
    submissions, out = Path(submissions), Path(out)
    students = sorted(p for p in submissions.iterdir() if p.is_dir() and not p.name.startswith("."))
    if not students:
        raise FileNotFoundError(f"no student folders in {submissions}")
    known = exercises(catalog) if Path(catalog).is_dir() else []
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
            reports[futures[future]] = future.result()
            bar.set_postfix(last=students[futures[future]].name)
            bar.update(1)
    rows = []
    for student, report in zip(students, reports):
        (logs / f"{student.name}.txt").write_text(report["output"], encoding="utf-8")
        earned = {e["exercise"]: e["earned"] for e in report["exercises"]}
        columns += [name for name in earned if name not in columns]
        texts += [e["exercise"] for e in report["exercises"]
                  if "text" in e and e["exercise"] not in texts]
        max_total = sum(e["points"] for e in known) if known else report["max_total"]
        row = {"student": student.name, **earned, "total": report["total"],
               "max_total": max_total, "error": report["error"] or ""}
        row.update({f"{e['exercise']}_text": e["text"] for e in report["exercises"]
                    if "text" in e})
        row.update({f"{e['exercise']}_rubric": rubric_summary(e["rubric"])
                    for e in report["exercises"] if "rubric" in e})
        row.update(_own_agent_fields(student, report))
        rows.append(row)
        (feedback / f"{student.name}.md").write_text(
            feedback_markdown(student.name, report, known, max_total), encoding="utf-8")
    out.parent.mkdir(parents=True, exist_ok=True)
    text_columns = [f"{name}_{part}" for name in texts for part in ("text", "rubric")]
    own_columns = list(CSV_COLUMNS) if OWN_AGENT_ITEM in columns else []  # lesson 13 graded
    with out.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=["student", *columns, "total", "max_total",
                                               "error", *own_columns, *text_columns])
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, 0) for c in columns}
                            | {c: row.get(c, "") for c in text_columns}
                            | {k: row[k] for k in ("student", "total", "max_total", "error")}
                            | {c: row.get(c, "") for c in own_columns})
    return rows


def _own_agent_fields(student: Path, report: dict[str, Any]) -> dict[str, Any]:
    """The class CSV's columns of a student's handed-in agent (:func:`csv_fields`), verified
    when the grader gave ``own_agent_report`` its points."""
    graded = [e for e in report["exercises"] if e["exercise"] == OWN_AGENT_ITEM]
    verified = None if not graded else all(e["earned"] == e["points"] for e in graded)
    try:
        folder = find_notebook(student, OWN_AGENT_NOTEBOOK).parent / SUBMISSION_DIR
    except ExerciseError:
        folder = None
    return csv_fields(folder, verified)


def leaderboard_markdown(rows: Iterable[dict[str, Any]]) -> str:
    """The class's own agents as a Markdown table, from :func:`grade`'s rows: the students
    whose report the grader verified first, by done % on the graded protocol (best first),
    then the claims it could not verify, then those who handed nothing in; ties by name."""
    def key(row):
        claimed = row.get("claimed_done_percent", "")
        rank = 0 if row.get("done_verified") == 1 else 1 if claimed != "" else 2
        return rank, -(claimed if claimed != "" else 0.0), row["student"]

    lines = ["| # | student | done % (graded protocol) | verified | transitions | episodes |",
             "|---|---|---|---|---|---|"]
    for place, row in enumerate(sorted(rows, key=key), start=1):
        claimed = row.get("claimed_done_percent", "")
        status = {1: "yes", 0: "no"}.get(row.get("done_verified"), "")
        lines.append(f"| {place} | {row['student']} | "
                     f"{'' if claimed == '' else f'{claimed:g}'} | {status} | "
                     f"{row.get('run_transitions', '')} | {row.get('run_episodes', '')} |")
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
    lines.append(f"TOTAL {total:g} / {max_total:g} points")
    return lines
