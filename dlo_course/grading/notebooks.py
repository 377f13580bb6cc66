"""The course's notebook files: reading and writing them, what each cell is (an exercise, a
written answer, setup), and releasing ``lessons/`` from ``solutions/``.

Conventions (nbgrader's, kept deliberately small):

* ``solutions/NN_topic.ipynb`` are the source of truth. ``lessons/`` is generated from them by
  :func:`release` (``dlo-course course release``) and never edited by hand.
* An **exercise** is a code cell that defines one function (or class) the student writes. The
  cell carries ``cell.metadata["dlo_course"] = {"exercise": NAME, "points": N}`` and starts
  with the comment ``# exercise: NAME (N points)``, which is also accepted on its own (a
  student may copy the cell and lose its metadata). NAME is the name of what the cell defines.
* The answer sits between ``### BEGIN SOLUTION`` and ``### END SOLUTION``. Releasing replaces
  each such block, markers included, by ``raise NotImplementedError()`` at the same
  indentation, so the signature and the docstring stay.
* A **written answer** is a Markdown cell in which the student writes prose (an analysis, a
  prediction made before running a cell). It carries ``cell.metadata["dlo_course"] =
  {"answer": NAME, "points": N, "min_words": W}`` and starts with the comment
  ``<!-- answer: NAME (N points, at least W words) -->`` (the fallback, as for exercises).
  The solution's cell holds notes for the instructor; releasing keeps only the comment and
  :data:`ANSWER_PLACEHOLDER`. **No pattern gives its points**: an answer that is missing or
  shorter than W words gets none (:func:`written_answer_problem`), said to the student; any
  other answer *awaits the instructor's review*, its points pending, and is recorded
  verbatim in the class CSV, where the instructor's points enter through a reviews file
  (:mod:`dlo_course.grading.reviews`). A keyword cannot tell "As I have not run the cell
  yet, I cannot say 1 thing about it here." from a prediction; a reader can.
* A written answer may instead be a **choice** among stated options: ``"choices": ["<one
  line>", ...]`` in the same metadata (2 to 26 options, labelled (a), (b), ... in that order).
  Its grade is automatic, being structured: its points for naming exactly one option's label
  in brackets, e.g. ``(b)`` (:func:`chosen_options`), none for no option or several.
  Releasing lists the options under the placeholder (:data:`CHOICES_PREFIX`); the student's
  reason, after the label, is for the discussion with the instructor. Use it where the
  lesson's question is a choice ("which of these will happen"), not to turn prose into one.
* A written answer may carry a **rubric**: ``"rubric": [{"criterion": "<one line the
  instructor and the student read>", "patterns": ["<case-insensitive Python regex>", ...]},
  ...]`` in the same metadata: the checklist the instructor reviews the answer against.
  Releasing keeps the rubric in the lesson's cell and lists the criteria under the
  placeholder (:data:`RUBRIC_PREFIX` ``(1) ...; (2) ...``), so the student sees what a good
  answer covers. The patterns (``re.search``, ignoring case: :func:`rubric_met`) earn
  nothing: the class CSV shows which criteria's patterns occur in an answer, as a hint for
  the reader ("no number found"), never as points. A malformed rubric fails the release and
  the grading (:func:`check_rubric`); ``dlo-course course rubrics`` prints every rubric for
  the instructor.
* **Setup** cells (tag ``setup`` in ``cell.metadata["tags"]``) hold what the exercises need
  (imports, constants). The grader runs only the setup cells and the exercise cells, in a fresh
  namespace, so it never waits for a simulation or a training run of the notebook.
* Notebooks are stored without outputs, in Jupyter's own JSON layout (so saving from Jupyter
  and writing from here give the same bytes).
* Notebooks read ``DLO_COURSE_FAST=1`` (:func:`dlo_course.notebook.fast_mode`) to shrink every
  simulation and training budget to seconds; the tests execute every solution that way.

Only the standard library is needed here: nbformat is optional (the ``notebooks`` extra).
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

from dlo_course.paths import REPO_ROOT

SOLUTION_BEGIN = "### BEGIN SOLUTION"
SOLUTION_END = "### END SOLUTION"
METADATA_KEY = "dlo_course"
SETUP_TAG = "setup"
PLACEHOLDER = ("# YOUR CODE HERE", "raise NotImplementedError()")
NOTEBOOK_GLOB = "[0-9][0-9]_*.ipynb"

SOLUTIONS_DIR = REPO_ROOT / "solutions"
LESSONS_DIR = REPO_ROOT / "lessons"
GRADING_TESTS_DIR = REPO_ROOT / "tests" / "grading"

_EXERCISE_COMMENT = re.compile(r"^\s*#\s*exercise:\s*([A-Za-z_]\w*)\s*\((\d+)\s*points?\)",
                               re.IGNORECASE)
ANSWER_PLACEHOLDER = "YOUR ANSWER HERE"
RUBRIC_PREFIX = "*Checked for:*"  # the line of a lesson's written answer that lists its criteria
CHOICES_PREFIX = "*Choose one, by its letter:*"  # the line that lists a choice's options
CHOICE_LABELS = "abcdefghijklmnopqrstuvwxyz"
_ANSWER_COMMENT = re.compile(r"^\s*<!--\s*answer:\s*([A-Za-z_]\w*)\s*\((\d+)\s*points?"
                             r"(?:\s*,\s*at least\s*(\d+)\s*words?)?\s*\)\s*-->", re.IGNORECASE)


def read_notebook(path: str | Path) -> dict[str, Any]:
    """A notebook as plain JSON (a dict), as nbformat 4 stores it."""
    with open(path, encoding="utf-8") as f:
        nb = json.load(f)
    if nb.get("nbformat") != 4 or not isinstance(nb.get("cells"), list):
        raise ValueError(f"{path} is not an nbformat 4 notebook")
    return nb


def notebook_json(nb: dict[str, Any]) -> str:
    """The exact text Jupyter (nbformat) writes for ``nb``: sorted keys, one-space indent."""
    return json.dumps(nb, sort_keys=True, indent=1, ensure_ascii=False) + "\n"


def write_notebook(nb: dict[str, Any], path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(notebook_json(nb), encoding="utf-8")
    return path


def cell_source(cell: dict[str, Any]) -> str:
    source = cell.get("source", "")
    return "".join(source) if isinstance(source, list) else source


def _set_source(cell: dict[str, Any], text: str) -> None:
    # Jupyter stores the source as a list of lines, each but the last ending in "\n".
    cell["source"] = text.splitlines(keepends=True)


def exercise_info(cell: dict[str, Any]) -> dict[str, Any] | None:
    """``{"exercise": name, "points": n}`` if ``cell`` is an exercise cell, else None.

    The metadata wins; a first-line comment ``# exercise: NAME (N points)`` is the fallback.
    """
    if cell.get("cell_type") != "code":
        return None
    meta = cell.get("metadata", {}).get(METADATA_KEY) or {}
    if "exercise" in meta:
        return {"exercise": str(meta["exercise"]), "points": int(meta.get("points", 1))}
    first = cell_source(cell).lstrip("\n").split("\n", 1)[0]
    match = _EXERCISE_COMMENT.match(first)
    if match:
        return {"exercise": match.group(1), "points": int(match.group(2))}
    return None


def check_rubric(rubric: Any, answer: str) -> list[dict[str, Any]]:
    """A written answer's rubric, checked: a non-empty list of ``{"criterion": text,
    "patterns": [regex, ...]}``, each criterion a non-empty line, each pattern a regex that
    compiles and cannot match every text. Raises ValueError naming ``answer`` otherwise."""
    where = f"written answer {answer!r}: rubric"
    if not isinstance(rubric, list) or not rubric:
        raise ValueError(f"{where} must be a non-empty list of {{\"criterion\": ..., "
                         f"\"patterns\": [...]}} (got {rubric!r}); leave the key out for none")
    checked = []
    for number, item in enumerate(rubric, start=1):
        if not isinstance(item, dict) or set(item) != {"criterion", "patterns"}:
            keys = sorted(item) if isinstance(item, dict) else type(item).__name__
            raise ValueError(f"{where} criterion {number} must have exactly the keys "
                             f"'criterion' and 'patterns' (got {keys})")
        criterion, patterns = item["criterion"], item["patterns"]
        if not isinstance(criterion, str) or not criterion.strip() or "\n" in criterion.strip():
            raise ValueError(f"{where} criterion {number}: 'criterion' must be one line of text "
                             f"(got {criterion!r})")
        if not isinstance(patterns, list) or not patterns \
                or not all(isinstance(p, str) and p for p in patterns):
            raise ValueError(f"{where} criterion {number} ({criterion!r}): 'patterns' must be a "
                             f"non-empty list of regular expressions (got {patterns!r})")
        for pattern in patterns:
            try:
                compiled = re.compile(pattern, re.IGNORECASE)
            except re.error as err:
                raise ValueError(f"{where} criterion {number} ({criterion!r}): pattern "
                                 f"{pattern!r} is not a valid regular expression: {err}") from None
            if compiled.search(""):
                raise ValueError(f"{where} criterion {number} ({criterion!r}): pattern "
                                 f"{pattern!r} matches the empty text, so any answer meets it")
        checked.append({"criterion": criterion.strip(), "patterns": list(patterns)})
    return checked


def check_choices(choices: Any, answer: str) -> list[str]:
    """A choice answer's options, checked: 2 to 26 distinct lines of text. Raises ValueError
    naming ``answer`` otherwise."""
    if not isinstance(choices, list) or not 2 <= len(choices) <= len(CHOICE_LABELS) \
            or not all(isinstance(c, str) and c.strip() and "\n" not in c.strip()
                       for c in choices) \
            or len({c.strip() for c in choices}) != len(choices):
        raise ValueError(f"written answer {answer!r}: choices must be a list of 2 to "
                         f"{len(CHOICE_LABELS)} distinct lines of text (got {choices!r})")
    return [c.strip() for c in choices]


def chosen_options(text: str, choices: list[str]) -> list[str]:
    """The labels of ``choices`` that ``text`` names in brackets (``(b)``, any case), sorted:
    a choice answer is made when there is exactly one."""
    labels = set(CHOICE_LABELS[:len(choices)])
    return sorted({m.group(1).lower() for m in re.finditer(r"\(([a-z])\)", text, re.IGNORECASE)}
                  & labels)


def choices_line(choices: list[str]) -> str:
    """The options as a lesson shows them under the placeholder:
    ``*Choose one, by its letter:* (a) ...; (b) ...``."""
    return f"{CHOICES_PREFIX} " + "; ".join(f"({label}) {choice}"
                                            for label, choice in zip(CHOICE_LABELS, choices))


def answer_info(cell: dict[str, Any]) -> dict[str, Any] | None:
    """``{"exercise": name, "points": n, "min_words": w, "kind": "text"}`` if ``cell`` is a
    written-answer cell (Markdown), else None; plus ``"rubric"`` (:func:`check_rubric`) and
    ``"choices"`` (:func:`check_choices`) if the metadata has them. The metadata wins; the first-line comment
    ``<!-- answer: NAME (N points, at least W words) -->`` is the fallback."""
    if cell.get("cell_type") != "markdown":
        return None
    meta = cell.get("metadata", {}).get(METADATA_KEY) or {}
    if "answer" in meta:
        info = {"exercise": str(meta["answer"]), "points": int(meta.get("points", 1)),
                "min_words": int(meta.get("min_words", 1)), "kind": "text"}
        if "rubric" in meta:
            info["rubric"] = check_rubric(meta["rubric"], info["exercise"])
        if "choices" in meta:
            info["choices"] = check_choices(meta["choices"], info["exercise"])
        return info
    first = cell_source(cell).lstrip("\n").split("\n", 1)[0]
    match = _ANSWER_COMMENT.match(first)
    if match:
        return {"exercise": match.group(1), "points": int(match.group(2)),
                "min_words": int(match.group(3) or 1), "kind": "text"}
    return None


def graded_info(cell: dict[str, Any]) -> dict[str, Any] | None:
    """What a graded cell is worth: :func:`exercise_info` (with ``"kind": "code"``) or
    :func:`answer_info`; None for any other cell."""
    info = exercise_info(cell)
    if info is not None:
        return {**info, "kind": "code"}
    return answer_info(cell)


def answer_text(cell: dict[str, Any]) -> str:
    """What the student wrote in a written-answer cell: the cell without its first-line
    comment, the placeholder and the released lists of criteria (:data:`RUBRIC_PREFIX`) and
    options (:data:`CHOICES_PREFIX`), stripped."""
    lines = cell_source(cell).strip("\n").split("\n")
    if lines and _ANSWER_COMMENT.match(lines[0]):
        lines = lines[1:]
    lines = [line for line in lines
             if not line.strip().startswith((RUBRIC_PREFIX, CHOICES_PREFIX))]
    return "\n".join(lines).replace(ANSWER_PLACEHOLDER, "").strip()


def _answer_info_in(cell: dict[str, Any], where: str) -> dict[str, Any] | None:
    try:
        return answer_info(cell)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None


def written_answers(path: str | Path) -> dict[str, dict[str, Any]]:
    """The written answers of a notebook: name -> :func:`answer_info` plus ``"text"``
    (:func:`answer_text`), ``"rubric"`` and ``"choices"`` (``[]`` if it has none). The last cell of a name
    wins, as for exercises. A malformed rubric raises ValueError naming the notebook."""
    found: dict[str, dict[str, Any]] = {}
    for cell in read_notebook(path)["cells"]:
        info = _answer_info_in(cell, Path(path).name)
        if info is not None:
            found[info["exercise"]] = {"rubric": [], "choices": [], **info,
                                       "text": answer_text(cell)}
    return found


def count_words(text: str) -> int:
    return len(re.findall(r"[^\W_]+(?:['’.-][^\W_]+)*", text))


def written_answer_problem(text: str, min_words: int) -> str | None:
    """Why a written answer gets no points (None: it is there and long enough, and awaits the
    instructor's review)."""
    words = count_words(text)
    if words == 0:
        return f"no answer written: replace {ANSWER_PLACEHOLDER!r} with your own words"
    if words < min_words:
        return (f"{words} word{'s' if words != 1 else ''}: this answer needs at least "
                f"{min_words} words")
    return None


def rubric_met(text: str, rubric: list[dict[str, Any]]) -> list[bool]:
    """For each criterion of ``rubric``: does any of its patterns occur in ``text``
    (``re.search``, ignoring case)? A hint for the instructor who reviews the answer, never
    its points: a digit and "as" are not a prediction."""
    return [any(re.search(p, text, re.IGNORECASE) for p in item["patterns"]) for item in rubric]


def rubric_line(rubric: list[dict[str, Any]]) -> str:
    """The criteria as a lesson shows them under the placeholder:
    ``*Checked for:* (1) ...; (2) ...``."""
    return f"{RUBRIC_PREFIX} " + "; ".join(f"({number}) {item['criterion']}"
                                           for number, item in enumerate(rubric, start=1))


def rubrics_markdown(folder: str | Path = SOLUTIONS_DIR) -> str:
    """Every written answer of the notebooks in ``folder`` with its points, minimum length
    and rubric (the criteria to review it against, and the patterns the class CSV reports
    as hints), as Markdown for the instructor."""
    lines = [f"# Written answers and their rubrics ({Path(folder).name}/)", "",
             "The instructor gives a written answer's points (reviews file of `dlo-course "
             "course grade`); the patterns only hint at what an answer contains.", ""]
    for path in notebooks_in(folder):
        answers = written_answers(path)
        if not answers:
            continue
        lines += [f"## {path.stem}", ""]
        for name, info in answers.items():
            points = f"{info['points']} point{'s' if info['points'] != 1 else ''}"
            if info["choices"]:
                lines.append(f"- `{name}`: {points}, a choice, graded automatically: "
                             + choices_line(info["choices"])[len(CHOICES_PREFIX) + 1:])
                continue
            lines.append(f"- `{name}`: {points}, at least {info['min_words']} words, "
                         "reviewed by the instructor" + ("" if info["rubric"] else "; no rubric"))
            for number, item in enumerate(info["rubric"], start=1):
                patterns = ", ".join(f"`{p}`" for p in item["patterns"])
                lines.append(f"  {number}. {item['criterion']} (any of: {patterns})")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def is_setup(cell: dict[str, Any]) -> bool:
    return cell.get("cell_type") == "code" and SETUP_TAG in cell.get("metadata", {}).get("tags", [])


def missing_data(nb: dict[str, Any]) -> list[Path]:
    """Data files a notebook needs (``metadata.dlo_course.requires``, relative to the data
    folder, e.g. ``databases/small.npz``) that do not exist yet."""
    from dlo_course.paths import DATA_DIR

    needed = nb.get("metadata", {}).get(METADATA_KEY, {}).get("requires", [])
    return [DATA_DIR / name for name in needed if not (DATA_DIR / name).is_file()]


def notebooks_in(folder: str | Path) -> list[Path]:
    """The course notebooks (``NN_*.ipynb``) of a folder, sorted."""
    return sorted(Path(folder).glob(NOTEBOOK_GLOB))


def strip_solutions(source: str) -> str:
    """Replace every ``### BEGIN SOLUTION`` ... ``### END SOLUTION`` block (markers included)
    by ``raise NotImplementedError()`` at the indentation of its BEGIN marker."""
    out: list[str] = []
    inside = False
    begin_line = 0
    for number, line in enumerate(source.split("\n"), start=1):
        stripped = line.strip()
        if stripped.startswith(SOLUTION_BEGIN):
            if inside:
                raise ValueError(f"line {number}: {SOLUTION_BEGIN} inside another solution")
            inside, begin_line = True, number
            indent = line[: len(line) - len(line.lstrip())]
            out += [indent + text for text in PLACEHOLDER]
        elif stripped.startswith(SOLUTION_END):
            if not inside:
                raise ValueError(f"line {number}: {SOLUTION_END} without {SOLUTION_BEGIN}")
            inside = False
        elif not inside:
            out.append(line)
    if inside:
        raise ValueError(f"line {begin_line}: {SOLUTION_BEGIN} is never closed")
    return "\n".join(out)


def clear_outputs(nb: dict[str, Any]) -> dict[str, Any]:
    """A copy of ``nb`` without outputs, execution counts or execution timing metadata."""
    nb = copy.deepcopy(nb)
    for cell in nb["cells"]:
        if cell.get("cell_type") == "code":
            cell["outputs"] = []
            cell["execution_count"] = None
        cell.get("metadata", {}).pop("execution", None)
    return nb


def has_outputs(nb: dict[str, Any]) -> bool:
    return any(cell.get("cell_type") == "code"
               and (cell.get("outputs") or cell.get("execution_count") is not None)
               for cell in nb["cells"])


def release_notebook(nb: dict[str, Any], name: str = "notebook") -> dict[str, Any]:
    """The student version of a solution notebook (outputs cleared, solutions removed)."""
    nb = clear_outputs(nb)
    for index, cell in enumerate(nb["cells"]):
        where = f"{name}, cell {index}"
        written = _answer_info_in(cell, where)
        if written is not None:  # the instructor's notes give way to the placeholder
            criteria = f"\n\n{rubric_line(written['rubric'])}" if written.get("rubric") else ""
            options = f"\n\n{choices_line(written['choices'])}" if written.get("choices") else ""
            words = written["min_words"]
            _set_source(cell, f"<!-- answer: {written['exercise']} ({written['points']} "
                              f"point{'s' if written['points'] != 1 else ''}, at least "
                              f"{words} word{'s' if words != 1 else ''}) -->\n"
                              f"{ANSWER_PLACEHOLDER}{options}{criteria}")
            continue
        if cell.get("cell_type") != "code":
            continue
        source = cell_source(cell)
        info = exercise_info(cell)
        if SOLUTION_BEGIN not in source:
            if info is not None:
                raise ValueError(f"{where}: exercise {info['exercise']!r} has no solution block")
            continue
        if info is None:
            raise ValueError(f"{where}: a solution block outside an exercise cell")
        if not re.search(rf"^(def|class)\s+{info['exercise']}\b", source, re.MULTILINE):
            raise ValueError(f"{where}: exercise cell must define {info['exercise']!r}")
        try:
            _set_source(cell, strip_solutions(source))
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
    return nb


def exercises(folder: str | Path) -> list[dict[str, Any]]:
    """Every graded cell of the notebooks in ``folder``, in order: notebook stem, name,
    points and kind ("code": an exercise; "text": a written answer, with its
    ``min_words``)."""
    found = []
    for path in notebooks_in(folder):
        for cell in read_notebook(path)["cells"]:
            info = exercise_info(cell)
            info = {**info, "kind": "code"} if info else _answer_info_in(cell, path.name)
            if info is not None:
                found.append({"notebook": path.stem, **info})
    return found


def release(solutions: str | Path = SOLUTIONS_DIR, lessons: str | Path = LESSONS_DIR,
            check: bool = False) -> list[str]:
    """Generate ``lessons/`` from ``solutions/``.

    Every ``NN_*.ipynb`` of ``solutions`` is written to ``lessons`` without outputs and with
    its solution blocks replaced (see :func:`release_notebook`); lesson notebooks without a
    solution are deleted.

    Args:
        check: write nothing; return the differences instead (an empty list: up to date).

    Returns:
        With ``check``: one line per out-of-date, missing or stray lesson. Otherwise the names
        of the notebooks written.
    """
    solutions, lessons = Path(solutions), Path(lessons)
    sources = notebooks_in(solutions)
    if not sources:
        raise FileNotFoundError(f"no notebooks NN_*.ipynb in {solutions}")
    names = [e["exercise"] for e in exercises(solutions)]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"exercise names must be unique across notebooks: {duplicates}")
    expected = {p.name: notebook_json(release_notebook(read_notebook(p), p.name))
                for p in sources}
    stray = [p for p in notebooks_in(lessons) if p.name not in expected]
    if check:
        problems = [f"{name}: missing from {lessons}" if not (lessons / name).is_file()
                    else f"{name}: differs from `dlo-course course release`"
                    for name, text in expected.items()
                    if not (lessons / name).is_file()
                    or (lessons / name).read_text(encoding="utf-8") != text]
        return problems + [f"{p.name}: has no solution notebook" for p in stray]
    lessons.mkdir(parents=True, exist_ok=True)
    for name, text in expected.items():
        (lessons / name).write_text(text, encoding="utf-8")
    for p in stray:
        p.unlink()
    return sorted(expected)
