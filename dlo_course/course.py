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

Grading (``dlo-course course grade``) runs ``pytest tests/grading --notebooks DIR`` for each
student's folder and collects the points of every exercise in a CSV file. The students' code
runs only in the :class:`Sandbox` (a child process per exercise, with limits, that sends back
plain data), and answers that use the library's references are rejected
(:func:`delegation_problems`). ``release_student`` writes the bundle handed to students. Only
the standard library is needed here: nbformat is optional (it is in the ``notebooks`` extra).
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
ANSWER_PLACEHOLDER = "YOUR ANSWER HERE"
_ANSWER_COMMENT = re.compile(r"^\s*<!--\s*answer:\s*([A-Za-z_]\w*)\s*\((\d+)\s*points?"
                             r"(?:\s*,\s*at least\s*(\d+)\s*words?)?\s*\)\s*-->", re.IGNORECASE)


# The notebooks' helpers live in dlo_course.notebook; re-exported here for notebooks written
# before it existed (``from dlo_course.course import fast_mode, output_dir``).
from dlo_course.notebook import fast_mode, output_dir  # noqa: E402,F401


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


# What a student bundle leaves out: the answers (solutions/) and the tests that quote, hold
# or run answers (the mutation suite quotes the solutions' lines, the calibration tests hold
# correct RingBuffer and build_mlp answers, the others grade solutions/), and the grader's
# own answers to the exercises the library has no reference for (tests/grading/answers.py),
# replaced by their probes' results as data (answers.json, :func:`record_answers`). The rest
# of the grader (tests/grading) stays, so that students can grade themselves: its other
# references are the library's, which the bundle ships anyway (the lessons import it). The
# lessons are written afresh from the solutions.
STUDENT_EXCLUDE = ("solutions/", "lessons/", "tests/test_course.py",
                   "tests/test_grading_attacks.py", "tests/test_grading_calibration.py",
                   "tests/test_mutations.py", "tests/grading/answers.py")
_NEVER_COPY = (".git/", ".venv", "runs/", "reports/", "__pycache__/", ".pytest_cache/",
               ".egg-info/", ".ipynb_checkpoints/")


def _repository_files(repo: Path) -> list[str]:
    """The repository's files (``git ls-files``; without git, a walk minus build and run
    folders), as POSIX paths relative to ``repo``."""
    try:
        out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others",
                              "--exclude-standard"], cwd=repo, capture_output=True,
                             check=True).stdout.decode()
        names = [n for n in out.split("\0") if n and (repo / n).is_file()]
        if names:
            return sorted(names)
    except (OSError, subprocess.CalledProcessError):
        pass
    names = []
    for path in repo.rglob("*"):
        rel = path.relative_to(repo).as_posix()
        if path.is_file() and not any(part in rel + "/" for part in _NEVER_COPY):
            names.append(rel)
    return sorted(names)


GRADING_ANSWERS = "answers.py"  # in the grading tests folder: the grader's own answers
RECORDED_ANSWERS = "answers.json"  # in a student bundle instead: their probes' results


def _module_from_file(path: str | Path, name: str):
    """Import a file that is not on sys.path (a grading test file, or the answers)."""
    import importlib.util
    import warnings

    module = sys.modules.get(name)
    if module is not None and getattr(module, "__file__", None) == str(path):
        return module
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    with warnings.catch_warnings():  # the test files' marks are registered by their conftest
        warnings.simplefilter("ignore")
        spec.loader.exec_module(module)
    sys.modules[name] = module
    return module


def answer_result(tests: str | Path, name: str, probe) -> Any:
    """``probe(answer)``, the answer being the grader's own ``name`` (``answers.py`` of the
    grading tests folder ``tests``). In a student bundle, which has no ``answers.py``, the
    result recorded at release (``answers.json``) instead. Runs in the grader's process."""
    tests = Path(tests)
    source = tests / GRADING_ANSWERS
    if source.is_file():
        answers = _module_from_file(source, "_dlo_grading_answers")
        return probe(getattr(answers, name))
    recorded = tests / RECORDED_ANSWERS
    if not recorded.is_file():
        raise FileNotFoundError(f"neither {source} nor {recorded}: the grader cannot check "
                                f"{name!r}")
    entry = json.loads(recorded.read_text())[name]
    if entry["probe"] != probe.__qualname__:
        raise ValueError(f"{recorded}: {name!r} was recorded for {entry['probe']}, not "
                         f"{probe.__qualname__}: release the bundle again")
    return decode_data(entry["value"])


def record_answers(tests: str | Path = GRADING_TESTS_DIR) -> dict[str, Any]:
    """The content of ``answers.json``: for each answer of ``tests/answers.py``
    (its ``PROBES``), the probe's name and its result on the answer, as plain data."""
    tests = Path(tests)
    answers = _module_from_file(tests / GRADING_ANSWERS, "_dlo_grading_answers")
    recorded = {}
    for name, (test_file, probe_name) in answers.PROBES.items():
        module = _module_from_file(tests / test_file, "_dlo_answers_" + Path(test_file).stem)
        probe = getattr(module, probe_name)
        recorded[name] = {"probe": probe_name,
                          "value": encode_data(probe(getattr(answers, name)))}
    return recorded


def release_student(dest: str | Path, repo: str | Path = REPO_ROOT,
                    solutions: str | Path = SOLUTIONS_DIR,
                    tests: str | Path = GRADING_TESTS_DIR) -> list[str]:
    """Write the student bundle: the repository without :data:`STUDENT_EXCLUDE` (no
    solutions, no test that holds answers), with ``lessons/`` released from ``solutions``
    and the grader's own answers (``tests/answers.py``, if any) replaced by their recorded
    results (``answers.json`` beside the bundle's copy of the grading tests).

    ``dest`` must not exist or be empty, and must lie outside ``repo``. ``tests`` is the
    grading tests folder, inside ``repo``. Returns the bundle's files (POSIX paths relative
    to ``dest``).
    """
    import shutil

    repo, dest = Path(repo).resolve(), Path(dest).resolve()
    if dest == repo or repo in dest.parents:
        raise ValueError(f"the student bundle must be written outside the repository: {dest}")
    if dest.exists() and any(dest.iterdir()):
        raise ValueError(f"{dest} is not empty")
    tests = Path(tests).resolve()
    exclude = (*STUDENT_EXCLUDE, (tests / GRADING_ANSWERS).relative_to(repo).as_posix())
    written = []
    for name in _repository_files(repo):
        if any(name == e or (e.endswith("/") and name.startswith(e)) for e in exclude):
            continue
        target = dest / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(repo / name, target)
        written.append(name)
    if (tests / GRADING_ANSWERS).is_file():
        target = dest / tests.relative_to(repo) / RECORDED_ANSWERS
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(json.dumps(record_answers(tests)) + "\n")
        written.append(target.relative_to(dest).as_posix())
    written += [f"lessons/{n}" for n in release(solutions, dest / "lessons")]
    lessons_readme = repo / "lessons" / "README.md"
    if lessons_readme.is_file():
        shutil.copy2(lessons_readme, dest / "lessons" / "README.md")
        written.append("lessons/README.md")
    for path in dest.rglob("*.ipynb"):  # the bundle's own check: no answer left behind
        text = path.read_text(encoding="utf-8")
        if SOLUTION_BEGIN in text or SOLUTION_END in text:
            raise ValueError(f"{path} still holds a solution block")
    return sorted(written)


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


class _CellTimeout(BaseException):
    """An earlier exercise cell ran out of its time (a BaseException: `except Exception` in
    the student's code does not swallow it)."""


class _time_limit:
    def __init__(self, seconds: float | None):
        self.seconds = seconds

    def __enter__(self):
        import signal

        if self.seconds and hasattr(signal, "setitimer"):
            def stop(signum, frame):
                raise _CellTimeout()

            self.previous = signal.signal(signal.SIGALRM, stop)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
        return self

    def __exit__(self, *exc):
        import signal

        if self.seconds and hasattr(signal, "setitimer"):
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.previous)
        return False


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

    def load(self, name: str, earlier_timeout: float | None = None) -> Any:
        """The object (function or class) called ``name`` defined by its exercise cell.

        The exercise cells above it run first (their errors ignored), so an exercise may use
        the student's earlier answers, as it would in the notebook. ``earlier_timeout``
        (seconds, Unix only): each of those cells is interrupted after that long, so a cell
        that never finishes costs only its own exercise.
        """
        source = self.source_of(name)
        ns = dict(self.namespace())
        for other, other_source in self.exercise_sources.items():
            if other_source is source:
                break
            try:
                with _time_limit(earlier_timeout):
                    exec(_compile(other_source, f"<{self.path.name} exercise {other}>"), ns)
            except (Exception, _CellTimeout):  # noqa: BLE001 - graded by its own test
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
          progress: bool = True, jobs: int = 1) -> list[dict[str, Any]]:
    """Grade every student folder in ``submissions`` and write one CSV row per student.

    Each sub-folder of ``submissions`` is one student (its name is the student's id) and holds
    that student's notebooks. Columns: ``student``, one column of points per exercise and
    written answer (in the order of the course), ``total``, ``max_total``, ``error`` (empty
    when grading ran), then one column ``<answer>_text`` per written answer holding what the
    student wrote, verbatim (its points only say that it is there and long enough).

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
            tqdm(total=len(students), unit="student", desc="grading",
                 disable=not progress, file=sys.stderr) as bar:
        futures = {pool.submit(grade_folder, student, tests, timeout): i
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
        rows.append(row)
        (feedback / f"{student.name}.md").write_text(
            feedback_markdown(student.name, report, known, max_total), encoding="utf-8")
    out.parent.mkdir(parents=True, exist_ok=True)
    text_columns = [f"{name}_text" for name in texts]
    with out.open("w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=["student", *columns, "total", "max_total",
                                               "error", *text_columns])
        writer.writeheader()
        for row in rows:
            writer.writerow({c: row.get(c, 0) for c in columns}
                            | {c: row.get(c, "") for c in text_columns}
                            | {k: row[k] for k in ("student", "total", "max_total", "error")})
    return rows


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
    exercise and, for each one that lost points, why: the failing check's message, without
    the grader's traceback. ``report`` is :func:`grade_folder`'s; ``known`` the course's
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


# ------------------------------------------------------------------- the sandbox
#
# Students' code never runs in the grader's process. A *server* process imports the heavy
# libraries once and never runs anything of a student; for every question the grader asks
# ("run probe P of test file F on exercise E of this notebook"), it forks a *worker* that
# restricts itself (memory, CPU time, file size; writes only inside a fresh scratch folder;
# no new processes (seccomp), no signals to other processes, ctypes or gc introspection (an
# audit hook); Linux Landlock too when the kernel has it), runs the notebook's setup cells and exercise cells, calls the probe on the
# student's object and writes what it returns, as plain data, to a result file. The grader
# decodes that data (JSON: it cannot carry code) and checks it against references it computes
# in its own, untouched process. A worker that hangs is killed at its time limit; one that
# crashes, patches a library or exits early only loses its own exercise.

SANDBOX_PRELOAD = (
    "numpy", "torch", "torch.nn", "torch.nn.functional", "gymnasium", "matplotlib",
    "matplotlib.pyplot", "pytest", "dlo_course", "dlo_course.ddpg", "dlo_course.replay_buffer",
    "dlo_course.noise", "dlo_course.env", "dlo_course.simulation", "dlo_course.mesh",
    "dlo_course.database", "dlo_course.evaluation", "dlo_course.trainer", "dlo_course.mpi",
    "dlo_course.plots", "dlo_course.demo", "dlo_course.notebook")
SANDBOX_MEMORY_MB = float(os.environ.get("DLO_COURSE_GRADING_MEMORY_MB", 3072))
_RESULT_LIMIT = 64 * 2**20  # bytes of one result, or any file (RLIMIT_FSIZE of the worker)


class DataError(TypeError):
    """A value that cannot travel between the sandbox and the grader as plain data."""


def encode_data(obj: Any, _depth: int = 0) -> Any:
    """``obj`` as JSON-compatible data: None, bool, int, float, str, bytes, list, tuple, dict,
    set, NumPy arrays and scalars, torch tensors (detached). Anything else raises DataError."""
    if _depth > 64:
        raise DataError("the value is nested too deeply")
    kind = type(obj)
    if obj is None or kind in (bool, int, float, str):
        return obj
    if kind in (list, tuple, set, frozenset, dict) or isinstance(obj, (list, tuple, dict)):
        if isinstance(obj, dict):
            return {"__dict__": [[encode_data(k, _depth + 1), encode_data(v, _depth + 1)]
                                 for k, v in obj.items()]}
        items = [encode_data(x, _depth + 1) for x in obj]
        if isinstance(obj, list):
            return items
        return {"__tuple__" if isinstance(obj, tuple) else "__set__": items}
    if isinstance(obj, (bytes, bytearray)):
        import base64

        return {"__bytes__": base64.b64encode(bytes(obj)).decode("ascii")}
    if isinstance(obj, (bool, int, float, str)):  # subclasses (IntEnum, numpy.float64, ...)
        import numpy as np

        if isinstance(obj, np.generic):
            return {"__scalar__": encode_data(np.asarray(obj), _depth + 1)}
        return (bool if isinstance(obj, bool) else int if isinstance(obj, int)
                else float if isinstance(obj, float) else str)(obj)
    module = getattr(kind, "__module__", "") or ""
    if module.startswith("torch") and hasattr(obj, "detach"):
        t = obj.detach().cpu()
        if str(t.dtype) == "torch.bfloat16":
            t = t.float()
        return {"__tensor__": encode_data(t.numpy(), _depth + 1),
                "requires_grad": bool(obj.requires_grad)}
    import numpy as np

    if isinstance(obj, np.generic):
        return {"__scalar__": encode_data(np.asarray(obj), _depth + 1)}
    if isinstance(obj, np.ndarray):
        import base64

        if obj.dtype.kind not in "biufc":
            return {"__objarray__": encode_data(obj.tolist(), _depth + 1)}
        return {"__ndarray__": [obj.dtype.str, list(obj.shape),
                                base64.b64encode(obj.tobytes(order="C")).decode("ascii")]}
    raise DataError(f"a {kind.__module__}.{kind.__qualname__} cannot be sent to the grader "
                    f"(only numbers, strings, containers, arrays and tensors)")


def decode_data(data: Any) -> Any:
    """The inverse of :func:`encode_data` (arrays are NumPy arrays, tensors torch tensors)."""
    if isinstance(data, list):
        return [decode_data(x) for x in data]
    if not isinstance(data, dict):
        return data
    if "__dict__" in data:
        return {_hashable(decode_data(k)): decode_data(v) for k, v in data["__dict__"]}
    if "__tuple__" in data:
        return tuple(decode_data(x) for x in data["__tuple__"])
    if "__set__" in data:
        return {_hashable(decode_data(x)) for x in data["__set__"]}
    if "__bytes__" in data:
        import base64

        return base64.b64decode(data["__bytes__"])
    import numpy as np

    if "__ndarray__" in data:
        import base64

        dtype, shape, payload = data["__ndarray__"]
        dtype = np.dtype(str(dtype))
        if dtype.kind not in "biufc":
            raise DataError(f"unexpected dtype {dtype}")
        return np.frombuffer(base64.b64decode(payload), dtype=dtype).reshape(
            [int(n) for n in shape]).copy()
    if "__objarray__" in data:
        return np.array(decode_data(data["__objarray__"]), dtype=object)
    if "__scalar__" in data:
        return decode_data(data["__scalar__"])[()]
    if "__tensor__" in data:
        import torch

        return torch.from_numpy(decode_data(data["__tensor__"]))
    raise DataError(f"unknown data {sorted(data)[:3]}")


def _hashable(value: Any) -> Any:
    if isinstance(value, list):
        return tuple(_hashable(v) for v in value)
    return value


def _landlock(scratch: str) -> bool:
    """Allow writes only beneath ``scratch`` (and, kernel permitting, no TCP and no signals
    to processes outside), with Linux Landlock. False where the kernel lacks it."""
    import ctypes

    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        abi = libc.syscall(444, None, ctypes.c_size_t(0), ctypes.c_uint32(1))
    except Exception:  # noqa: BLE001 - not Linux, or no syscall(): no Landlock
        return False
    if abi < 1:
        return False
    fs = sum(1 << bit for bit in (1, 4, 5, 6, 7, 8, 9, 10, 11, 12))  # write, remove, make
    if abi >= 2:
        fs |= 1 << 13  # refer (link/rename across folders)
    if abi >= 3:
        fs |= 1 << 14  # truncate

    class Ruleset(ctypes.Structure):
        _fields_ = [("fs", ctypes.c_uint64), ("net", ctypes.c_uint64),
                    ("scoped", ctypes.c_uint64)]

    class PathBeneath(ctypes.Structure):
        _pack_ = 1
        _fields_ = [("allowed", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]

    ruleset = Ruleset(fs, 3 if abi >= 4 else 0, 3 if abi >= 6 else 0)
    size = 8 if abi < 4 else 16 if abi < 6 else 24
    fd = libc.syscall(444, ctypes.byref(ruleset), ctypes.c_size_t(size), ctypes.c_uint32(0))
    if fd < 0:
        return False
    folder = os.open(scratch, os.O_PATH | os.O_DIRECTORY)
    rule = PathBeneath(fs, folder)
    ok = libc.syscall(445, fd, 1, ctypes.byref(rule), ctypes.c_uint32(0)) == 0
    ok = ok and libc.prctl(38, 1, 0, 0, 0) == 0  # PR_SET_NO_NEW_PRIVS
    ok = ok and libc.syscall(446, fd, ctypes.c_uint32(0)) == 0
    os.close(folder)
    os.close(fd)
    if not ok:
        raise OSError(ctypes.get_errno(), "Landlock could not restrict the sandbox")
    return True


def _seccomp_no_processes() -> bool:
    """Forbid new processes and programs (fork, vfork, clone without CLONE_THREAD, execve)
    with a seccomp filter, so that nothing escapes the audit hook through a fresh process
    (``_posixsubprocess.fork_exec``, which multiprocessing and subprocess call, raises no
    audit event). Threads stay allowed. False where seccomp or the architecture is missing."""
    import ctypes
    import platform

    machine = platform.machine()
    if not sys.platform.startswith("linux"):
        return False
    if machine in ("x86_64", "AMD64"):
        arch, forbidden, clone, clone3 = 0xC000003E, (57, 58, 59, 322), 56, 435
    elif machine in ("aarch64", "arm64"):
        arch, forbidden, clone, clone3 = 0xC00000B7, (221, 281), 220, 435
    else:
        return False
    ld, jeq, jset, ret = 0x20, 0x15, 0x45, 0x06
    allow, eperm, enosys = 0x7FFF0000, 0x00050000 | 1, 0x00050000 | 38
    program = [(ld, 0, 0, 4), (jeq, 1, 0, arch), (ret, 0, 0, allow), (ld, 0, 0, 0)]
    if arch == 0xC000003E:  # the x32 ABI's system calls: none of ours
        program += [(0x35, 0, 1, 0x40000000), (ret, 0, 0, eperm)]  # jge
    for number in forbidden:
        program += [(jeq, 0, 1, number), (ret, 0, 0, eperm)]
    program += [(jeq, 0, 1, clone3), (ret, 0, 0, enosys)]  # libc falls back to clone
    program += [(jeq, 0, 4, clone), (ld, 0, 0, 16),  # clone: its flags, args[0]
                (jset, 0, 1, 0x00010000), (ret, 0, 0, allow), (ret, 0, 0, eperm)]
    program += [(ret, 0, 0, allow)]

    class Instruction(ctypes.Structure):
        _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8),
                    ("k", ctypes.c_uint32)]

    class Program(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.POINTER(Instruction))]

    instructions = (Instruction * len(program))(*[Instruction(*i) for i in program])
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(38, 1, 0, 0, 0) != 0:  # PR_SET_NO_NEW_PRIVS
            return False
        fprog = Program(len(program), instructions)
        return libc.prctl(22, 2, ctypes.byref(fprog), 0, 0) == 0  # PR_SET_SECCOMP, FILTER
    except (OSError, AttributeError):
        return False


def _install_audit_hook(scratch: str) -> None:
    """An audit hook (it cannot be removed) that refuses, from here on: writing, creating,
    deleting or renaming files outside ``scratch``; subprocesses and forks; signals to other
    processes; sockets; ctypes; walking the garbage collector (to reach the hook)."""
    # Everything the hook uses is bound here, so that patching os, builtins or this module
    # afterwards changes nothing.
    fspath, getcwd, getpid, stat, s_isdir = os.fspath, os.getcwd, os.getpid, os.stat, \
        __import__("stat").S_ISDIR
    from pathlib import PosixPath, PurePosixPath

    path_types = (str, bytes, PosixPath, PurePosixPath)
    type_of, str_type, int_type, tuple_type = type, str, int, tuple
    denied_error = PermissionError
    root = scratch.rstrip("/") + "/"
    write_flags = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND
    directory_flag = getattr(os, "O_DIRECTORY", 0)
    own_pid = getpid()
    refused = frozenset({
        "os.system", "os.exec", "os.posix_spawn", "os.spawn", "os.fork", "os.forkpty",
        "subprocess.Popen", "pty.spawn", "os.symlink", "os.link", "os.mkfifo", "os.mknod",
        "ctypes.dlopen", "ctypes.dlsym", "ctypes.call_function", "ctypes.cdata",
        "ctypes.addressof", "ctypes.PyObj_FromPtr", "ctypes.string_at", "ctypes.wstring_at",
        "ctypes.cdata/buffer", "gc.get_objects", "gc.get_referrers", "gc.get_referents",
        "socket.connect", "socket.bind", "socket.sendto", "socket.sendmsg",
        "resource.setrlimit", "resource.prlimit", "sys.remote_exec", "os.setpgid"})
    path_events = {"os.remove": 1, "os.rmdir": 1, "os.rename": 2, "os.mkdir": 1,
                   "os.truncate": 1, "os.chmod": 1, "os.chown": 1, "os.utime": 1,
                   "os.chflags": 1, "os.lchflags": 1, "os.setxattr": 1, "os.removexattr": 1,
                   "shutil.rmtree": 1, "sqlite3.connect": 1, "shutil.move": 2,
                   "shutil.copyfile": 2, "shutil.copytree": 2}

    def normalised(path):
        if type_of(path) is bytes:
            path = path.decode("utf-8", "surrogateescape")
        elif type_of(path) is not str_type:
            path = fspath(path)
        if not path.startswith("/"):
            path = getcwd() + "/" + path
        parts = []
        for part in path.split("/"):
            if part in ("", "."):
                continue
            if part == "..":
                if parts:
                    parts.pop()
            else:
                parts.append(part)
        return "/" + "/".join(parts) + "/"

    def inside(path):
        if type_of(path) is int_type:  # an already opened file descriptor
            return True
        if type_of(path) not in path_types:
            return False
        return normalised(path).startswith(root)

    def hook(event, args):
        if event == "open":
            path, mode, flags = args
            if type_of(mode) is str_type:
                writing = "w" in mode or "a" in mode or "x" in mode or "+" in mode
            else:
                writing = bool(flags & write_flags)
            if writing and not inside(path):
                raise denied_error(f"the grader's sandbox refuses to write {path!r}: write "
                                   "only inside the current (scratch) folder")
            if mode is None and not inside(path) and type_of(path) in path_types:
                # os.open of a folder outside could serve as dir_fd= for a write there
                try:
                    is_folder = (flags & directory_flag) or s_isdir(stat(path).st_mode)
                except OSError:
                    is_folder = False
                if is_folder:
                    raise denied_error(f"the grader's sandbox refuses to open the folder "
                                       f"{path!r}")
        elif event in refused:
            raise denied_error(f"the grader's sandbox refuses {event}")
        elif event in path_events:
            for path in args[:path_events[event]]:
                if not inside(path):
                    raise denied_error(f"the grader's sandbox refuses {event} on {path!r} "
                                       "(outside the scratch folder)")
        elif event in ("os.kill", "os.killpg"):
            if args[0] not in (own_pid, 0) or event == "os.killpg":
                raise denied_error("the grader's sandbox refuses signals to other processes")
        elif event == "signal.pthread_kill":
            pass

    sys.addaudithook(hook)


def _restrict_worker(scratch: str, timeout: float, memory_mb: float) -> None:
    import resource

    def vm_bytes() -> int:
        try:
            with open("/proc/self/statm") as f:
                return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError):
            return 0

    if sys.platform.startswith("linux"):  # die with the server, even while sleeping
        import ctypes

        try:
            ctypes.CDLL(None).prctl(1, 9, 0, 0, 0)  # PR_SET_PDEATHSIG, SIGKILL
        except (OSError, AttributeError):
            pass
    limits = [(resource.RLIMIT_CPU, int(timeout) + 2),
              (resource.RLIMIT_FSIZE, _RESULT_LIMIT), (resource.RLIMIT_CORE, 0)]
    if memory_mb > 0:
        limits.append((resource.RLIMIT_AS, vm_bytes() + int(memory_mb * 2**20)))
    for which, value in limits:
        try:
            resource.setrlimit(which, (value, value))
        except (ValueError, OSError):
            pass
    if os.environ.get("DLO_COURSE_SANDBOX_LANDLOCK", "1") != "0":  # "0": tests of the hook
        try:
            _landlock(scratch)
        except OSError:
            pass
    _seccomp_no_processes()
    torch_c = sys.modules.get("torch._C")
    if torch_c is not None and hasattr(torch_c, "PyTorchFileWriter"):
        # torch.save(obj, path) writes from C++, unseen by the audit hook: ask it first
        writer, audit = torch_c.PyTorchFileWriter, sys.audit

        def checked_writer(name, *args, **kwargs):
            if not hasattr(name, "write"):
                audit("open", name, "wb", 0)
            return writer(name, *args, **kwargs)

        torch_c.PyTorchFileWriter = checked_writer
    _install_audit_hook(scratch)


GRADER_ONLY = ("reference_", "library_", "check_")  # test-file helpers never sent to a sandbox


def _load_probe(path: str, name: str):
    """The probe ``name`` of the test file ``path``, loaded in the worker without the file's
    grader-only helpers (:data:`GRADER_ONLY`: reference answers, checks), which the student's
    code could otherwise reach through the probe's globals."""
    import importlib.util

    module_name = "_dlo_probe_" + re.sub(r"\W", "_", Path(path).stem)
    module = sys.modules.get(module_name)
    if module is None:
        spec = importlib.util.spec_from_file_location(module_name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[module_name] = module
        spec.loader.exec_module(module)
        for key in [k for k in vars(module) if k.startswith(GRADER_ONLY)]:
            delattr(module, key)
    obj = module
    for part in name.split("."):
        obj = getattr(obj, part)
    return obj


def _resolve(dotted: str) -> Any:
    import importlib

    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for part in parts[k:]:
            obj = getattr(obj, part)
        return obj
    raise ImportError(dotted)


def _poison(references: Iterable[str]) -> None:
    """Make the library's reference implementations raise when called (all their aliases,
    since the code of the function objects themselves is replaced)."""
    for dotted in references:
        try:
            obj = _resolve(dotted)
        except (ImportError, AttributeError):
            continue
        functions = [obj]
        if isinstance(obj, type):
            functions = [v for v in vars(obj).values()]
        for fn in functions:
            if isinstance(fn, property):
                fn = fn.fget
            fn = getattr(fn, "__func__", getattr(fn, "func", fn))
            code = getattr(fn, "__code__", None)
            if code is None or code.co_freevars:
                continue
            text = (f"def stub(*args, **kwargs):\n    raise RuntimeError("
                    f"{('the answer calls ' + dotted + ', the library reference of this exercise: write it yourself')!r})\n")
            scope: dict[str, Any] = {}
            exec(text, scope)  # noqa: S102 - our own, fixed text
            fn.__code__ = scope["stub"].__code__


def _worker(request: dict[str, Any], result_fd: int) -> None:
    """In the forked worker: restrict, load the exercise, run the probe, write the result."""
    scratch = request["scratch"]
    os.chdir(scratch)
    tmp = os.path.join(scratch, "tmp")
    os.makedirs(tmp, exist_ok=True)
    os.environ.update(TMPDIR=tmp, MPLCONFIGDIR=tmp, HOME=scratch)
    tempfile.tempdir = tmp
    _restrict_worker(scratch, request["timeout"], request["memory_mb"])
    response: dict[str, Any]
    try:
        probe = _load_probe(request["probe_file"], request["probe"])
        args = decode_data(request["args"])
        if request["notebook"] is None:  # a reference run (MPI): the probe uses the library
            response = {"status": "ok", "value": encode_data(probe(None, *args))}
        else:
            book = ExerciseNotebook.from_path(request["notebook"])
            try:
                obj = book.load(request["exercise"], earlier_timeout=request["timeout"] / 10)
            except ExerciseError as err:
                response = {"status": "not loaded", "message": str(err)}
            else:
                _poison(request.get("references", ()))
                value = probe(obj, *args)
                response = {"status": "ok", "value": encode_data(value)}
    except BaseException as err:  # noqa: BLE001 - anything the student's code raises
        import traceback

        frames = traceback.extract_tb(err.__traceback__)
        student = [f for f in frames if f.filename != __file__] or frames[-3:]
        text = "".join(traceback.format_list(student)) + \
            "".join(traceback.format_exception_only(type(err), err))
        response = {"status": "error", "message": text.strip()}
    payload = json.dumps(response).encode()
    view = memoryview(payload)
    while view:
        view = view[os.write(result_fd, view):]
    os.close(result_fd)


def sandbox_server() -> None:
    """The sandbox server's main loop (``python -c 'from dlo_course.course import
    sandbox_server; sandbox_server()'``): one JSON request per line on stdin, one JSON reply
    per line on stdout. It never runs a student's code itself."""
    import select
    import signal
    import time

    proto_in = os.fdopen(os.dup(0), "r")
    proto_out = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)  # whatever the libraries print goes to stderr, not into the protocol
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    import importlib

    for name in SANDBOX_PRELOAD:
        try:
            importlib.import_module(name)
        except Exception as err:  # noqa: BLE001
            print(f"sandbox: could not preload {name}: {err}", file=sys.stderr)
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    proto_out.write(json.dumps({"ready": True}) + "\n")
    proto_out.flush()
    private = {proto_in.fileno(), proto_out.fileno()}
    for line in proto_in:
        request = json.loads(line)
        scratch = request["scratch"]
        result_path = os.path.join(os.path.dirname(scratch), os.path.basename(scratch) + ".json")
        log_path = os.path.join(scratch, "output.txt")
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the worker
            code = 0
            try:
                os.setpgid(0, 0)
                for fd in private:
                    os.close(fd)
                log = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                os.dup2(log, 1)
                os.dup2(log, 2)
                os.close(log)
                result_fd = os.open(result_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                _worker(request, result_fd)
            except BaseException:  # noqa: BLE001
                code = 3
            finally:
                try:
                    sys.stdout.flush()
                    sys.stderr.flush()
                finally:
                    os._exit(code)
        deadline = time.monotonic() + float(request["timeout"])
        status = None
        while True:
            done, wait_status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.monotonic() > deadline:
                for kill in (lambda: os.killpg(pid, signal.SIGKILL),
                             lambda: os.kill(pid, signal.SIGKILL)):
                    try:
                        kill()
                    except OSError:
                        pass
                os.waitpid(pid, 0)
                status = "timeout"
                break
            select.select([], [], [], 0.005)
        if status is None:
            if os.WIFSIGNALED(wait_status):
                sig = os.WTERMSIG(wait_status)
                status = "killed" if sig != signal.SIGXCPU else "timeout"
                reason = f"killed by signal {sig}"
            else:
                status, reason = "exited", f"exit code {os.WEXITSTATUS(wait_status)}"
        else:
            reason = "time limit"
        try:  # a process group member left behind (the hook refuses forks; just in case)
            os.killpg(pid, signal.SIGKILL)
        except OSError:
            pass
        proto_out.write(json.dumps({"status": status, "reason": reason,
                                    "result": result_path, "log": log_path}) + "\n")
        proto_out.flush()


class SandboxError(Exception):
    """The sandbox itself failed (it could not start, or it stopped answering)."""


class Sandbox:
    """The grader's side of the sandbox: starts the server lazily, asks it to run probes,
    restarts it if it ever dies, and decodes the results.

    Args:
        timeout: wall-clock (and CPU) seconds of one probe.
        memory_mb: address space a worker may add to what the server has mapped.
    """

    def __init__(self, timeout: float = 60.0, memory_mb: float = SANDBOX_MEMORY_MB):
        self.timeout, self.memory_mb = float(timeout), float(memory_mb)
        self._tmp = tempfile.TemporaryDirectory(prefix="dlo-grading-")
        self.root = Path(self._tmp.name).resolve()
        self._proc: subprocess.Popen | None = None
        self._count = 0

    def _start(self) -> None:
        env = dict(os.environ, MPLBACKEND="Agg", DLO_COURSE_FAST="1", OMP_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="1",
                   MPLCONFIGDIR=str(self.root / "mpl"),
                   DLO_COURSE_OUTPUT=str(self.root / "output"))
        env.pop("PYTHONSTARTUP", None)
        log = open(self.root / "server.log", "ab")
        self._proc = subprocess.Popen(
            [sys.executable, "-c", "from dlo_course.course import sandbox_server; "
                                   "sandbox_server()"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, cwd=self.root, env=env)
        log.close()
        reply = self._read(max(120.0, self.timeout))
        if not reply.get("ready"):
            raise SandboxError("the grading sandbox did not start")

    def _read(self, timeout: float) -> dict[str, Any]:
        import select

        assert self._proc is not None and self._proc.stdout is not None
        ready, _, _ = select.select([self._proc.stdout], [], [], timeout)
        line = self._proc.stdout.readline() if ready else b""
        if not line:
            self.close()
            tail = ""
            if (self.root / "server.log").is_file():
                tail = (self.root / "server.log").read_text(errors="replace")[-2000:]
            raise SandboxError(f"the grading sandbox stopped answering\n{tail}")
        return json.loads(line)

    def run(self, notebook: str | Path, exercise: str, probe_file: str | Path, probe: str,
            args: tuple = (), references: Iterable[str] = ()) -> dict[str, Any]:
        """Run ``probe(obj, *args)`` in a fresh worker, ``obj`` being what the exercise cell
        of ``notebook`` defines. Returns ``status`` ("ok", "not loaded", "error", "timeout",
        "killed", "exited"), ``value`` (decoded data, if ok), ``message`` and ``output``
        (what the worker printed)."""
        if self._proc is None or self._proc.poll() is not None:
            self._start()
        self._count += 1
        scratch = self.root / f"scratch{self._count:04d}"
        scratch.mkdir()
        copy_path = scratch / Path(notebook).name
        copy_path.write_bytes(Path(notebook).read_bytes())
        request = {"scratch": str(scratch), "notebook": str(copy_path), "exercise": exercise,
                   "probe_file": str(Path(probe_file).resolve()), "probe": probe,
                   "args": encode_data(tuple(args)), "references": list(references),
                   "timeout": self.timeout, "memory_mb": self.memory_mb}
        assert self._proc is not None and self._proc.stdin is not None
        try:
            self._proc.stdin.write((json.dumps(request) + "\n").encode())
            self._proc.stdin.flush()
        except OSError as err:
            self.close()
            raise SandboxError(f"the grading sandbox is gone: {err}") from err
        reply = self._read(self.timeout + 60)
        output = ""
        log = Path(reply["log"])
        if log.is_file():
            output = log.read_bytes()[-20_000:].decode(errors="replace")
        result: dict[str, Any] = {"status": reply["status"], "output": output, "value": None,
                                  "message": ""}
        path = Path(reply["result"])
        if reply["status"] == "timeout":
            result["message"] = f"the exercise ran longer than its time limit ({self.timeout:g} s)"
        elif path.is_file() and path.stat().st_size and reply["status"] == "exited":
            try:
                data = json.loads(path.read_text())
                result.update(status=str(data["status"]), message=str(data.get("message", "")))
                if result["status"] == "ok":
                    result["value"] = decode_data(data["value"])
            except (ValueError, KeyError, TypeError, RecursionError) as err:
                result.update(status="error", message=f"unreadable result: {err!r:.300}")
        else:
            result.update(status="error" if reply["status"] == "exited" else reply["status"],
                          message=f"the exercise's process ended without a result "
                                  f"({reply['reason']})")
        path.unlink(missing_ok=True)
        import shutil

        shutil.rmtree(scratch, ignore_errors=True)
        return result

    def close(self) -> None:
        if self._proc is not None:
            for stream in (self._proc.stdin, self._proc.stdout):
                try:
                    stream.close()
                except (OSError, AttributeError):
                    pass
            try:
                self._proc.kill()
                self._proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                pass
            self._proc = None

    def __del__(self):
        self.close()


# ------------------------------------------------------------ sandboxed MPI ranks
#
# An exercise written with mpi4py is graded in real MPI processes. The grader starts
# ``mpiexec -n N python -c "...mpi_sandbox_rank()" REQUEST`` in a fresh folder: every rank
# initialises MPI and exchanges a few messages of every size class first (so the connections
# and shared-memory segments MPI uses exist before the doors close), then restricts itself as
# a sandbox worker does (:func:`_restrict_worker`, its own scratch folder ``rank<r>/``), runs
# the probe on the student's object and writes its result as data. The grader, which never
# imports mpi4py, reads the N results. A rank that hangs (a student's collective that the
# other rank never joins) is killed with the whole launcher at the time limit.


def mpi_sandbox_rank() -> None:
    """One rank of :func:`run_mpi` (``sys.argv[1]``: the request file)."""
    import importlib

    request = json.loads(Path(sys.argv[1]).read_text())
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    rank = comm.Get_rank()
    scratch = os.path.join(request["root"], f"rank{rank}")
    os.makedirs(scratch, exist_ok=True)
    log = os.open(os.path.join(scratch, "output.txt"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
                  0o600)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    for name in SANDBOX_PRELOAD:
        try:
            importlib.import_module(name)
        except Exception as err:  # noqa: BLE001
            print(f"sandbox: could not preload {name}: {err}", file=sys.stderr)
    import numpy as np
    import torch

    torch.set_num_threads(1)
    for n in (1, 1024, 1 << 18):  # eager and rendezvous messages, before the restrictions
        buf = np.ones(n, np.float32)
        comm.Allreduce(MPI.IN_PLACE, buf)
        comm.Bcast(buf, root=0)
    comm.allgather(rank)
    comm.Barrier()
    result_fd = os.open(os.path.join(request["root"], f"rank{rank}.json"),
                        os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    _worker(dict(request, scratch=scratch), result_fd)
    sys.stdout.flush()
    sys.stderr.flush()


def find_mpiexec() -> Path | None:
    """The ``mpiexec`` beside this Python (the mpich wheel's), or the first on the PATH."""
    import shutil

    beside = Path(sys.executable).parent / "mpiexec"
    if beside.is_file():
        return beside
    found = shutil.which("mpiexec")
    return Path(found) if found else None


def run_mpi(notebook: str | Path | None, exercise: str, probe_file: str | Path, probe: str,
            args: tuple = (), references: Iterable[str] = (), ranks: int = 2,
            timeout: float = 60.0, memory_mb: float = SANDBOX_MEMORY_MB,
            startup: float = 120.0) -> list[dict[str, Any]]:
    """Run ``probe(obj, *args)`` in ``ranks`` sandboxed MPI processes, ``obj`` being what the
    exercise cell of ``notebook`` defines (``notebook=None``: ``obj`` is None, a reference
    run of a probe that then uses the library).

    Returns:
        One dict per rank, as :meth:`Sandbox.run`: ``status``, ``value``, ``message``,
        ``output``.

    Raises:
        SandboxError: no ``mpiexec`` (``pip install mpich``, the ``mpi`` extra).
    """
    import shutil
    import signal

    mpiexec = find_mpiexec()
    if mpiexec is None:
        raise SandboxError("grading this exercise needs mpiexec: pip install mpich mpi4py")
    with tempfile.TemporaryDirectory(prefix="dlo-grading-mpi-") as tmp:
        root = Path(tmp).resolve()
        copy_path = None
        if notebook is not None:
            copy_path = root / Path(notebook).name
            copy_path.write_bytes(Path(notebook).read_bytes())
        request = {"root": str(root), "notebook": None if copy_path is None else str(copy_path),
                   "exercise": exercise, "probe_file": str(Path(probe_file).resolve()),
                   "probe": probe, "args": encode_data(tuple(args)),
                   "references": list(references), "timeout": float(timeout),
                   "memory_mb": float(memory_mb)}
        (root / "request.json").write_text(json.dumps(request))
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("PMI", "PMIX", "MPI", "OMPI", "HYDRA"))}
        env.update(MPLBACKEND="Agg", DLO_COURSE_FAST="1", OMP_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="1",
                   MPLCONFIGDIR=str(root / "mpl"), DLO_COURSE_OUTPUT=str(root / "output"))
        env.pop("PYTHONSTARTUP", None)
        proc = subprocess.Popen(
            [str(mpiexec), "-n", str(int(ranks)), sys.executable, "-c",
             "from dlo_course.course import mpi_sandbox_rank; mpi_sandbox_rank()",
             str(root / "request.json")],
            cwd=root, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, start_new_session=True)
        timed_out = False
        try:
            launcher, _ = proc.communicate(timeout=timeout + startup)
        except subprocess.TimeoutExpired:
            timed_out = True
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except OSError:
                pass
            launcher, _ = proc.communicate()
        try:  # a rank left behind by the launcher
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        launcher_text = launcher.decode(errors="replace")[-3000:]
        results = []
        for rank in range(int(ranks)):
            log = root / f"rank{rank}" / "output.txt"
            output = log.read_bytes()[-20_000:].decode(errors="replace") if log.is_file() else ""
            result: dict[str, Any] = {"status": "error", "value": None, "output": output,
                                      "message": ""}
            path = root / f"rank{rank}.json"
            text = path.read_text() if path.is_file() else ""
            if text:
                try:
                    data = json.loads(text)
                    result.update(status=str(data["status"]), message=str(data.get("message", "")))
                    if result["status"] == "ok":
                        result["value"] = decode_data(data["value"])
                except (ValueError, KeyError, TypeError, RecursionError) as err:
                    result.update(status="error", message=f"unreadable result: {err!r:.300}")
            elif timed_out:
                result.update(status="timeout", message=f"the exercise ran longer than its "
                                                        f"time limit ({timeout:g} s)")
            else:
                result["message"] = (f"rank {rank} ended without a result (mpiexec exit code "
                                     f"{proc.returncode})\n{launcher_text}")
            results.append(result)
        shutil.rmtree(root, ignore_errors=True)
    return results


# ---------------------------------------------------------------- delegation

LIBRARY = "dlo_course"
LIBRARY_HELPERS = ("dlo_course.notebook", "dlo_course.course")  # fast_mode, output_dir: no answers
_DYNAMIC = {"__import__": "__import__", "importlib": "importlib", "eval": "eval",
            "exec": "exec", "compile": "compile", "globals": "globals()"}


def _library_names(sources: Iterable[str]) -> dict[str, str]:
    """Names that the cells bind to the library: name -> dotted path (``ddpg`` ->
    ``dlo_course.ddpg``, ``ReplayBuffer`` -> ``dlo_course.replay_buffer.ReplayBuffer``)."""
    import ast

    bound: dict[str, str] = {}
    for source in sources:
        try:
            tree = ast.parse(_strip_magics(source))
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == LIBRARY or alias.name.startswith(LIBRARY + "."):
                        if alias.asname:
                            bound[alias.asname] = alias.name
                        else:
                            bound[alias.name.split(".")[0]] = LIBRARY
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and (
                    node.module == LIBRARY or node.module.startswith(LIBRARY + ".")):
                for alias in node.names:
                    bound[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return bound


def _strip_magics(source: str) -> str:
    return "\n".join("" if line.lstrip().startswith(("%", "!")) else line
                     for line in source.split("\n"))


def delegation_problems(source: str, context: Iterable[str] = (),
                        references: Iterable[str] = ()) -> list[str]:
    """Why an exercise cell's ``source`` is not the student's own work, if it is not: it uses
    the ``dlo_course`` library (which holds the reference answers) other than its
    ``dlo_course.course`` helpers, whether by a name that ``context`` (the setup and other
    exercise cells) or the cell imports, by subclassing, or through ``getattr``,
    ``importlib``, ``__import__``, ``sys.modules``, ``eval``/``exec`` or a string naming the
    library; or it names a class of ``references`` outside the library (``torch.optim.Adam``
    for an Adam step written by hand). An empty list: nothing wrong."""
    import ast

    try:
        tree = ast.parse(_strip_magics(source))
    except SyntaxError:
        return []  # the sandbox reports the syntax error itself
    bound = _library_names([*context, source])
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    problems: list[str] = []

    def add(text: str) -> None:
        if text not in problems:
            problems.append(text)

    def allowed(dotted: str) -> bool:
        return any(dotted == h or dotted.startswith(h + ".") for h in LIBRARY_HELPERS)

    outside = {}  # a class name of a reference outside the library -> its dotted path
    for dotted in references:
        if not dotted.startswith(LIBRARY + "."):
            parts = dotted.split(".")
            names = [p for p in parts if p[:1].isupper()] or parts[-1:]
            outside[names[0]] = ".".join(parts[:parts.index(names[0]) + 1])
    for node in ast.walk(tree):
        name = node.id if isinstance(node, ast.Name) else \
            node.attr if isinstance(node, ast.Attribute) else None
        if name in outside:
            add(f"uses {outside[name]}")
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                if top == LIBRARY and not allowed(alias.name):
                    add(f"imports {alias.name}")
                elif top == "importlib":
                    add("imports importlib")
        elif isinstance(node, ast.ImportFrom) and node.module:
            top = node.module.split(".")[0]
            if top == LIBRARY and not allowed(node.module):
                add(f"imports from {node.module}")
            elif top == "importlib":
                add("imports from importlib")
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
            if node.id in bound:
                dotted, current = bound[node.id], node
                while isinstance(parents.get(current), ast.Attribute) \
                        and parents[current].value is current:
                    current = parents[current]
                    dotted += "." + current.attr
                if not allowed(dotted):
                    add(f"uses {dotted}")
            elif node.id in _DYNAMIC:
                add(f"uses {_DYNAMIC[node.id]}")
            elif node.id == "getattr":
                call = parents.get(node)
                if isinstance(call, ast.Call) and call.args and any(
                        isinstance(n, ast.Name) and n.id in bound for n in ast.walk(call.args[0])):
                    add("uses getattr on the library")
        elif isinstance(node, ast.Attribute) and node.attr == "modules" \
                and isinstance(node.value, ast.Name) and node.value.id == "sys":
            add("uses sys.modules")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and LIBRARY in node.value:
            add(f"names the library in a string ({node.value!r})")
    return problems


def delegation_message(name: str, problems: list[str]) -> str:
    return (f"{name}: rejected, the answer is not written in the exercise cell: it "
            f"{'; '.join(problems)}. The dlo_course library holds the reference answers, so "
            f"an exercise cell may not call, subclass or fetch anything of it (its helpers "
            f"in dlo_course.notebook excepted): write the code yourself.")
