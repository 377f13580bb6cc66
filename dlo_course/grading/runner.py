"""Running the exercises of a student's notebook: :class:`ExerciseNotebook` runs its setup
cells and exercise cells (never the rest of the notebook) and returns what an exercise cell
defines. Used inside the sandbox's worker (:mod:`dlo_course.grading.sandbox`), never in the
grader's own process.
"""

from __future__ import annotations

import linecache
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dlo_course.grading.notebooks import cell_source, exercise_info, is_setup, read_notebook


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
