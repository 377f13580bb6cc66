"""A student's feedback sheet (Markdown): the points of every exercise, the criteria each
written answer met and missed, and, for each exercise that lost points, the failing check's
message without the grader's traceback.
"""

from __future__ import annotations

import re
from typing import Any

from dlo_course.grading.notebooks import count_words

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
    """One student's feedback sheet (Markdown): the total, a table of the points of every
    exercise, each written answer's rubric (the criteria met and not met) and, for each one
    that lost points, why: the failing check's message, without the grader's traceback. ``report`` is :func:`grade_folder`'s; ``known`` the course's
    exercises (:func:`exercises`), so that a notebook not handed in still shows its
    exercises."""
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
    lines = [f"# Feedback: {student}", "", f"**Total: {total:g} / {max_total:g} points.**", ""]
    if report.get("error"):
        lines += [f"The grader could not grade this folder: {feedback_message(report['error'])}",
                  ""]
    lines += ["| notebook | exercise | points | result |", "|---|---|---|---|"]
    for e in entries:
        result = "passed" if e.get("earned", 0) == e["points"] else e.get("outcome", "failed")
        if "text" in e:
            words = count_words(e["text"])
            result += f" (written answer, {words} word{'s' if words != 1 else ''})"
        lines.append(f"| {e['notebook']} | `{e['exercise']}` | {e.get('earned', 0):g} / "
                     f"{e['points']:g} | {result} |")
    # what the grader found ("met" per criterion); not a catalog's rubric of an ungraded answer
    rubrics = [e for e in entries if e.get("rubric") and "met" in e["rubric"][0]]
    if rubrics:
        lines += ["", "## Written answers: what each was checked for", ""]
        for e in rubrics:
            lines.append(f"- `{e['exercise']}` ({e['notebook']}), {e.get('earned', 0):g} / "
                         f"{e['points']:g}:")
            lines += [f"  - [{'x' if item['met'] else ' '}] {item['criterion']}"
                      f"{'' if item['met'] else ' (not met)'}" for item in e["rubric"]]
    lost = [e for e in entries if e.get("earned", 0) < e["points"]]
    if lost:
        lines += ["", "## What to look at", ""]
        for e in lost:
            message = feedback_message(e.get("message", "")) or e.get("outcome", "failed")
            fence = "````" if "```" in message else "```"
            lines += [f"### `{e['exercise']}` ({e['notebook']}): {e.get('earned', 0):g} / "
                      f"{e['points']:g}", "", fence + "text", message, fence, ""]
    else:
        lines += ["", "Every check passed."]
    return "\n".join(lines).rstrip() + "\n"


def rubric_summary(rubric: list[dict[str, Any]] | None) -> str:
    """A written answer's rubric result in one line, for the class CSV: ``"1/2 met; missing:
    gives a reason"`` (``""`` without a rubric)."""
    if not rubric:
        return ""
    missing = [item["criterion"] for item in rubric if not item["met"]]
    summary = f"{len(rubric) - len(missing)}/{len(rubric)} met"
    return summary + (f"; missing: {'; '.join(missing)}" if missing else "")
