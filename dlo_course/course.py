"""The course's notebooks: releasing lessons from solutions, extracting exercises, grading.

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
* **Setup** cells (tag ``setup`` in ``cell.metadata["tags"]``) hold what the exercises need
  (imports, constants). The grader runs only the setup cells and the exercise cells, in a fresh
  namespace, so it never waits for a simulation or a training run of the notebook.
* Notebooks are stored without outputs, in Jupyter's own JSON layout (so saving from Jupyter
  and writing from here give the same bytes).
* Notebooks read ``DLO_COURSE_FAST=1`` (:func:`fast_mode`) to shrink every simulation and
  training budget to seconds; the tests execute every solution that way.

Grading (``dlo-course course grade``) runs ``pytest tests/grading --notebooks DIR`` for each
student's folder and collects the points of every exercise in a CSV file. Only the standard
library is needed here: nbformat is optional (it is in the ``notebooks`` extra).
"""

from __future__ import annotations

import copy
import csv
import json
import linecache
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

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


# --------------------------------------------------------------------------- budgets


def fast_mode() -> bool:
    """True when ``DLO_COURSE_FAST`` is set (to anything but "", "0", "false", "no"):
    notebooks then shrink episodes, steps and training runs to a few seconds."""
    return os.environ.get("DLO_COURSE_FAST", "").strip().lower() not in ("", "0", "false", "no")


def output_dir(*parts: str) -> Path:
    """Where notebooks write pictures, GIFs and runs: ``$DLO_COURSE_OUTPUT`` or, by default,
    ``reports/lessons`` in the repository (ignored by git). Created if missing."""
    base = Path(os.environ.get("DLO_COURSE_OUTPUT", REPO_ROOT / "reports" / "lessons"))
    path = base.joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


# ----------------------------------------------------------------- notebook files


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


# ------------------------------------------------------------------------ release


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
    """Every exercise of the notebooks in ``folder``: notebook stem, name, points, in order."""
    found = []
    for path in notebooks_in(folder):
        for cell in read_notebook(path)["cells"]:
            info = exercise_info(cell)
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


# --------------------------------------------------------------------- extraction


class ExerciseError(Exception):
    """An exercise could not be extracted from a notebook (missing, or its cell fails)."""


def _compile(source: str, filename: str):
    """Compile a cell without its IPython-only lines (magics, shell escapes), and register
    its text so that tracebacks show the student's lines."""
    text = "\n".join("" if line.lstrip().startswith(("%", "!")) else line
                     for line in source.split("\n"))
    linecache.cache[filename] = (len(text), None, text.splitlines(keepends=True), filename)
    return compile(text, filename, "exec")


@dataclass
class ExerciseNotebook:
    """The exercises of one notebook, loaded without running the rest of it.

    :meth:`namespace` runs the setup cells once in a fresh namespace; :meth:`load` runs, in a
    copy of it, the exercise cells above the requested one (errors ignored) and then that
    cell, and returns the object the cell defines. A failing or missing exercise cell only
    affects that exercise (and the later ones that use it).
    """

    path: Path
    setup_sources: list[str] = field(default_factory=list)
    exercise_sources: dict[str, str] = field(default_factory=dict)
    code_sources: list[str] = field(default_factory=list)
    _namespace: dict[str, Any] | None = None
    _setup_error: str | None = None
    _setup_started: bool = False

    @classmethod
    def from_path(cls, path: str | Path) -> "ExerciseNotebook":
        path = Path(path)
        nb = read_notebook(path)
        book = cls(path)
        for cell in nb["cells"]:
            if is_setup(cell):
                book.setup_sources.append(cell_source(cell))
            info = exercise_info(cell)
            if info is not None:  # the last cell of a name wins (a student's retry)
                book.exercise_sources.pop(info["exercise"], None)  # keep notebook order
                book.exercise_sources[info["exercise"]] = cell_source(cell)
        book.code_sources = [cell_source(c) for c in nb["cells"] if c.get("cell_type") == "code"]
        return book

    def namespace(self) -> dict[str, Any]:
        """The setup cells' namespace (run once; raises ExerciseError if a setup cell fails)."""
        if self._namespace is not None:
            return self._namespace
        if self._setup_error is not None:
            raise ExerciseError(self._setup_error)
        if self._setup_started:  # an earlier attempt never finished (it was timed out)
            self._setup_error = f"{self.path.name}: a setup cell did not finish"
            raise ExerciseError(self._setup_error)
        self._setup_started = True
        ns: dict[str, Any] = {"__name__": "__notebook__"}
        for k, source in enumerate(self.setup_sources):
            try:
                exec(_compile(source, f"<{self.path.name} setup cell {k}>"), ns)
            except Exception as err:  # noqa: BLE001 - any error of the student's code
                self._setup_error = (f"{self.path.name}: setup cell {k} failed: "
                                     f"{type(err).__name__}: {err}")
                raise ExerciseError(self._setup_error) from err
        self._namespace = ns
        return ns

    def source_of(self, name: str) -> str:
        if name in self.exercise_sources:
            return self.exercise_sources[name]
        # Fallback: a code cell that defines the name at top level (metadata and comment lost).
        pattern = re.compile(rf"^(def|class)\s+{re.escape(name)}\b", re.MULTILINE)
        for source in reversed(self.code_sources):
            if pattern.search(source):
                return source
        raise ExerciseError(f"{self.path.name}: no exercise cell for {name!r}")

    def load(self, name: str) -> Any:
        """The object (function or class) called ``name`` defined by its exercise cell.

        The exercise cells above it run first (their errors ignored), so an exercise may use
        the student's earlier answers, as it would in the notebook.
        """
        source = self.source_of(name)
        ns = dict(self.namespace())
        for other, other_source in self.exercise_sources.items():
            if other_source is source:
                break
            try:
                exec(_compile(other_source, f"<{self.path.name} exercise {other}>"), ns)
            except Exception:  # noqa: BLE001 - graded by its own test
                pass
        error: Exception | None = None
        try:
            exec(_compile(source, f"<{self.path.name} exercise {name}>"), ns)
        except Exception as err:  # noqa: BLE001
            error = err
        obj = ns.get(name)
        if obj is None or obj is self.namespace().get(name):
            detail = f": {type(error).__name__}: {error}" if error else ""
            raise ExerciseError(f"{self.path.name}: the exercise cell does not define "
                                f"{name!r}{detail}")
        if getattr(obj, "__module__", None) != ns["__name__"]:
            raise ExerciseError(f"{self.path.name}: {name!r} must be written in the exercise "
                                f"cell, not imported (it comes from {obj.__module__})")
        return obj  # defined before the cell failed (e.g. a failing demo line): still graded


def find_notebook(folder: str | Path, stem: str) -> Path:
    """``folder/stem.ipynb``, or the only file of that name below ``folder``."""
    folder = Path(folder)
    direct = folder / f"{stem}.ipynb"
    if direct.is_file():
        return direct
    found = sorted(p for p in folder.rglob(f"{stem}.ipynb") if ".ipynb_checkpoints" not in p.parts)
    if not found:
        raise ExerciseError(f"no notebook {stem}.ipynb in {folder}")
    return found[0]


# ------------------------------------------------------------------------ grading


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


def grade_folder(notebooks: str | Path, tests: str | Path = GRADING_TESTS_DIR,
                 timeout: float = 1800) -> dict[str, Any]:
    """Grade one folder of notebooks in a pytest subprocess.

    Returns:
        The grader's JSON report (``exercises``: notebook, exercise, points, earned, outcome;
        ``total``, ``max_total``), plus ``returncode``, ``output`` (pytest's text) and
        ``error`` (None, or why there is no report).
    """
    with tempfile.TemporaryDirectory() as tmp:
        report_path = Path(tmp) / "grades.json"
        env = dict(os.environ, MPLBACKEND="Agg", DLO_COURSE_FAST="1",
                   DLO_COURSE_OUTPUT=str(Path(tmp) / "output"))
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
          progress: bool = True) -> list[dict[str, Any]]:
    """Grade every student folder in ``submissions`` and write one CSV row per student.

    Each sub-folder of ``submissions`` is one student (its name is the student's id) and holds
    that student's notebooks. Columns: ``student``, one column of points per exercise (in the
    order of the course), ``total``, ``max_total`` and ``error`` (empty when grading ran).
    The grader's full output for each student (what failed, and why) is written beside the
    CSV, in ``<out stem>_logs/<student>.txt``, for feedback.

    Args:
        catalog: folder whose notebooks list the exercises (the solutions), so every student
            gets every column even if their notebook is missing.
    """
    submissions, out = Path(submissions), Path(out)
    students = sorted(p for p in submissions.iterdir() if p.is_dir() and not p.name.startswith("."))
    if not students:
        raise FileNotFoundError(f"no student folders in {submissions}")
    known = exercises(catalog) if Path(catalog).is_dir() else []
    columns = [e["exercise"] for e in known]
    logs = out.parent / f"{out.stem}_logs"
    logs.mkdir(parents=True, exist_ok=True)
    rows = []
    for k, student in enumerate(students, start=1):
        if progress:
            print(f"[{k}/{len(students)}] grading {student.name} ...", file=sys.stderr, flush=True)
        report = grade_folder(student, tests, timeout)
        (logs / f"{student.name}.txt").write_text(report["output"], encoding="utf-8")
        earned = {e["exercise"]: e["earned"] for e in report["exercises"]}
        columns += [name for name in earned if name not in columns]
        max_total = sum(e["points"] for e in known) if known else report["max_total"]
        rows.append({"student": student.name, **earned, "total": report["total"],
                     "max_total": max_total, "error": report["error"] or ""})
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["student", *columns, "total", "max_total", "error"])
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, 0) for c in columns} | {
                k: row[k] for k in ("student", "total", "max_total", "error")})
    return rows


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
