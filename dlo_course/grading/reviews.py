"""The instructor's review of the written answers: the only way they earn points.

A pattern cannot tell a prediction from "As I have not run the cell yet, I cannot say 1 thing
about it here.", so the grader gives a written answer no points of its own: one that is there
and long enough *awaits review*, its points pending (``tests/grading/conftest.py``). The
instructor reads it in the class CSV and enters its points in a **reviews file**, a CSV with
the columns ``student``, ``exercise`` (the written answer's name), ``points`` and optionally
``comment`` (shown on the student's feedback sheet), given to ``dlo-course course grade
--reviews FILE``; a row whose ``points`` is empty is not reviewed yet. ``course grade`` also
writes ``<out stem>_reviews.csv`` beside the class CSV: one row per written answer that can be
reviewed, with the student's text and the points already given, ready to fill in and pass
back (it keeps the points and comments it was given, so the same file can go round again).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Iterable

REVIEW_COLUMNS = ("student", "exercise", "points", "max_points", "comment", "text")
REVIEWED = "reviewed"  # the outcome of a written answer the instructor gave points


def read_reviews(path: str | Path, students: Iterable[str] = (),
                 answers: dict[str, float] | None = None) -> dict[tuple[str, str], dict]:
    """The reviews of ``path``: (student, exercise) -> ``{"points", "comment"}``, the rows with
    points only. Raises ValueError, naming the line, for a file without the columns, points
    that are not a number from 0 up, a student not in ``students`` (when given), or an
    exercise that is not one of ``answers`` (written answer -> its points, when given) or
    gets more than its points."""
    students = set(students)
    reviews: dict[tuple[str, str], dict] = {}
    with Path(path).open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        missing = {"student", "exercise", "points"} - set(reader.fieldnames or ())
        if missing:
            raise ValueError(f"{path}: a reviews file needs the columns student, exercise and "
                             f"points (missing: {', '.join(sorted(missing))})")
        for row in reader:
            where = f"{path}, line {reader.line_num}"
            student, name = (row["student"] or "").strip(), (row["exercise"] or "").strip()
            text = (row["points"] or "").strip()
            if not text:
                continue  # not reviewed yet
            try:
                points = float(text)
            except ValueError:
                points = math.nan
            if not math.isfinite(points) or points < 0:
                raise ValueError(f"{where}: points must be a number from 0 up (got {text!r})")
            if students and student not in students:
                raise ValueError(f"{where}: no student {student!r} is graded")
            if answers is not None:
                if name not in answers:
                    raise ValueError(f"{where}: {name!r} is not a written answer to review "
                                     "(one of the course's answers in prose)")
                if points > answers[name]:
                    raise ValueError(f"{where}: {name!r} is worth {answers[name]:g} "
                                     f"point{'s' if answers[name] != 1 else ''} (got {points:g})")
            if (student, name) in reviews:
                raise ValueError(f"{where}: {student}'s {name!r} is reviewed twice")
            reviews[(student, name)] = {"points": points,
                                        "comment": (row.get("comment") or "").strip()}
    return reviews


def apply_reviews(report: dict[str, Any], student: str,
                  reviews: dict[tuple[str, str], dict]) -> list[str]:
    """Give the written answers of ``student``'s grades ``report`` (:func:`grade_folder`'s)
    the instructor's points: a reviewed answer's ``earned`` is the review's, its outcome
    :data:`REVIEWED`, its ``pending`` gone, the comment under ``review_comment``; the total
    follows. A review can also give points to an answer the grader found too short. Returns
    the reviews of ``student`` that found no written answer in the report (its notebook was
    not graded), by name."""
    mine = {name: review for (who, name), review in reviews.items() if who == student}
    for entry in report.get("exercises", []):
        review = mine.pop(entry["exercise"], None)
        if review is None or "text" not in entry or entry.get("choices"):
            continue
        if review["points"] > entry["points"]:
            raise ValueError(f"{student}'s {entry['exercise']!r} is worth {entry['points']:g} "
                             f"points (reviewed: {review['points']:g})")
        entry.update(earned=review["points"], outcome=REVIEWED,
                     review_comment=review["comment"])
        entry.pop("pending", None)
    report["total"] = sum(e["earned"] for e in report.get("exercises", []))
    return sorted(mine)


def review_rows(student: str, report: dict[str, Any]) -> list[dict[str, Any]]:
    """The rows of the reviews file to fill in for ``student``: every written answer in
    prose the grader recorded (not a choice, whose grade is automatic), with the points
    already reviewed (empty while pending, and for a missing or too-short answer, whose 0
    stands unless the instructor writes points)."""
    return [{"student": student, "exercise": e["exercise"],
             "points": f"{e['earned']:g}" if e.get("outcome") == REVIEWED else "",
             "max_points": f"{e['points']:g}", "comment": e.get("review_comment", ""),
             "text": e["text"]}
            for e in report.get("exercises", []) if "text" in e and not e.get("choices")]


def write_review_file(path: str | Path, rows: Iterable[dict[str, Any]]) -> Path:
    """Write the reviews file to fill in (:func:`review_rows` of every student)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(REVIEW_COLUMNS))
        writer.writeheader()
        writer.writerows(rows)
    return path
