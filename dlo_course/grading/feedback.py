"""A student's feedback sheet (Markdown): the points of every exercise, the written answers
awaiting the instructor's review (with what the instructor reads them for) and, for each
exercise that lost points, the failing check's message without the grader's traceback.
"""

from __future__ import annotations

import re
from typing import Any

from dlo_course.grading.notebooks import count_words
from dlo_course.grading.reviews import REVIEWED

FEEDBACK_MESSAGE_LIMIT = 1500  # characters of one failing check's message in a feedback sheet


_FRAME = re.compile(r'^\s*File "([^"]*)", line \d+')


def feedback_message(message: str) -> str:
    """A failing check's message as a student should read it: without pytest's "Failed: "
    prefix, without the traceback frames of the grader's files (a frame of the student's own
    cells, ``<... exercise NAME>``, stays: it points at their line), and cut to
    :data:`FEEDBACK_MESSAGE_LIMIT` characters."""
    text = str(message or "").strip()
    if text.startswith("Failed: "):
        text = text[len("Failed: "):]
    kept, skipping = [], False
    for line in text.split("\n"):
        frame = _FRAME.match(line)
        if frame:
            skipping = not frame.group(1).startswith("<")
        elif skipping and not line.startswith(" "):
            skipping = False  # the frame's indented source lines are over
        if not skipping:
            kept.append(line)
    text = "\n".join(kept).strip()
    if len(text) > FEEDBACK_MESSAGE_LIMIT:
        text = text[:FEEDBACK_MESSAGE_LIMIT].rstrip() + "\n[...]"
    return text


def feedback_markdown(student: str, report: dict[str, Any],
                      known: list[dict[str, Any]] | None = None,
                      max_total: float | None = None) -> str:
    """One student's feedback sheet (Markdown): the total and the points awaiting review, a
    table of the points of every exercise (a written answer that is there awaits the
    instructor's review: not failed, not passed), the criteria the instructor reads each
    written answer for, with the instructor's comment once reviewed, and, for each exercise
    that lost points, why: the failing check's message, without the grader's traceback.
    ``report`` is :func:`grade_folder`'s (reviews applied:
    :func:`dlo_course.grading.reviews.apply_reviews`); ``known`` the course's exercises
    (:func:`exercises`), so that a notebook not handed in still shows its exercises."""
    graded = {e["exercise"]: e for e in report.get("exercises", [])}
    known = list(known or [])
    entries = [graded.get(e["exercise"], {**e, "earned": 0, "outcome": "not graded",
                                          "message": f"{e['notebook']}.ipynb was not found "
                                                     "or could not be graded"})
               for e in known]
    listed = {e["exercise"] for e in known}
    entries += [e for name, e in graded.items() if name not in listed]
    if max_total is None:
        max_total = sum(e["points"] for e in entries)
    total = sum(e.get("earned", 0) for e in entries)
    pending = sum(e.get("pending", 0) for e in entries)
    lines = [f"# Feedback: {student}", "", f"**Total: {total:g} / {max_total:g} points.**"
             + (f" {pending:g} more await your instructor's review (written answers: no "
                "pattern gives their points, your instructor does)." if pending else ""), ""]
    if report.get("error"):
        lines += [f"The grader could not grade this folder: {feedback_message(report['error'])}",
                  ""]
    lines += ["| notebook | exercise | points | result |", "|---|---|---|---|"]
    for e in entries:
        lines.append(f"| {e['notebook']} | `{e['exercise']}` | {_points(e)} / "
                     f"{e['points']:g} | {_result(e)} |")
    # the written answers graded (a catalog's rubric of an answer not handed in has no text)
    written = [e for e in entries if "text" in e and (e.get("rubric") or e.get("review_comment"))]
    if written:
        lines += ["", "## Written answers: what your instructor reads them for", ""]
        for e in written:
            lines.append(f"- `{e['exercise']}` ({e['notebook']}), {_points(e)} / "
                         f"{e['points']:g}:")
            lines += [f"  - {item['criterion']}" for item in e.get("rubric", [])]
            if e.get("review_comment"):
                lines.append(f"  - Your instructor: {e['review_comment']}")
    lost = [e for e in entries if e.get("earned", 0) < e["points"] and not e.get("pending")]
    if lost:
        lines += ["", "## What to look at", ""]
        for e in lost:
            message = (feedback_message(e.get("message", "")) or e.get("review_comment")
                       or e.get("outcome", "failed"))
            fence = "````" if "```" in message else "```"
            lines += [f"### `{e['exercise']}` ({e['notebook']}): {e.get('earned', 0):g} / "
                      f"{e['points']:g}", "", fence + "text", message, fence, ""]
    else:
        lines += ["", "Every check passed." + (" The written answers await your instructor's "
                                               "review." if pending else "")]
    return "\n".join(lines).rstrip() + "\n"


def _points(entry: dict[str, Any]) -> str:
    return "pending" if entry.get("pending") else f"{entry.get('earned', 0):g}"


def _result(entry: dict[str, Any]) -> str:
    """The table's word for an exercise: passed, awaiting the instructor's review, reviewed,
    or why it lost points; a written answer also says how long it is."""
    if entry.get("pending"):
        result = "awaiting the instructor's review"
    elif entry.get("outcome") == REVIEWED:
        result = "reviewed by the instructor"
    elif entry.get("earned", 0) == entry["points"]:
        result = "passed"
    else:
        result = entry.get("outcome", "failed")
    if "text" in entry:
        words = count_words(entry["text"])
        result += f" (written answer, {words} word{'s' if words != 1 else ''})"
    return result


def rubric_summary(rubric: list[dict[str, Any]] | None) -> str:
    """Which criteria of a written answer's rubric have their patterns in the answer, in one
    line for the reviewer in the class CSV: ``"hint, not points: patterns of 1/2 criteria
    found; none for: gives a reason"`` (``""`` without a rubric). A vacuous answer can have
    them all ("1 thing", "as"), and a good one can miss one: the reviewer decides."""
    if not rubric:
        return ""
    missing = [item["criterion"] for item in rubric if not item["patterns_found"]]
    summary = (f"hint, not points: patterns of {len(rubric) - len(missing)}/{len(rubric)} "
               "criteria found")
    return summary + (f"; none for: {'; '.join(missing)}" if missing else "")
