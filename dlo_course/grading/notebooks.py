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
  :data:`ANSWER_PLACEHOLDER`. It is scored for presence and length only
  (:func:`written_answer_problem`) and recorded verbatim in the class CSV, for the
  instructor to read.
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


def answer_info(cell: dict[str, Any]) -> dict[str, Any] | None:
    """``{"exercise": name, "points": n, "min_words": w, "kind": "text"}`` if ``cell`` is a
    written-answer cell (Markdown), else None. The metadata wins; the first-line comment
    ``<!-- answer: NAME (N points, at least W words) -->`` is the fallback."""
    if cell.get("cell_type") != "markdown":
        return None
    meta = cell.get("metadata", {}).get(METADATA_KEY) or {}
    if "answer" in meta:
        return {"exercise": str(meta["answer"]), "points": int(meta.get("points", 1)),
                "min_words": int(meta.get("min_words", 1)), "kind": "text"}
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
    comment and without the placeholder, stripped."""
    lines = cell_source(cell).strip("\n").split("\n")
    if lines and _ANSWER_COMMENT.match(lines[0]):
        lines = lines[1:]
    return "\n".join(lines).replace(ANSWER_PLACEHOLDER, "").strip()


def written_answers(path: str | Path) -> dict[str, dict[str, Any]]:
    """The written answers of a notebook: name -> :func:`answer_info` plus ``"text"``
    (:func:`answer_text`). The last cell of a name wins, as for exercises."""
    found: dict[str, dict[str, Any]] = {}
    for cell in read_notebook(path)["cells"]:
        info = answer_info(cell)
        if info is not None:
            found[info["exercise"]] = {**info, "text": answer_text(cell)}
    return found


def count_words(text: str) -> int:
    return len(re.findall(r"[^\W_]+(?:['’.-][^\W_]+)*", text))


def written_answer_problem(text: str, min_words: int) -> str | None:
    """Why a written answer gets no points (None: full points). Only its presence and length
    count here; what it says is for the instructor, who reads it in the class CSV."""
    words = count_words(text)
    if words == 0:
        return f"no answer written: replace {ANSWER_PLACEHOLDER!r} with your own words"
    if words < min_words:
        return (f"{words} word{'s' if words != 1 else ''}: this answer needs at least "
                f"{min_words} words")
    return None


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
        written = answer_info(cell)
        if written is not None:  # the instructor's notes give way to the placeholder
            _set_source(cell, f"<!-- answer: {written['exercise']} ({written['points']} "
                              f"point{'s' if written['points'] != 1 else ''}, at least "
                              f"{written['min_words']} words) -->\n{ANSWER_PLACEHOLDER}")
            continue
        if cell.get("cell_type") != "code":
            continue
        source = cell_source(cell)
        info = exercise_info(cell)
        where = f"{name}, cell {index}"
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
            info = graded_info(cell)
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
