"""Autograding of the lesson notebooks.

Run ``python -m pytest tests/grading`` to grade ``lessons/`` (where every exercise fails until
it is solved), or ``python -m pytest tests/grading --notebooks DIR`` to grade the notebooks in
``DIR`` (a student's folder, or ``solutions``). ``--grades-json FILE`` also writes the points as
JSON (``dlo-course course grade`` uses it).

These tests are collected only when targeted: the plain ``python -m pytest`` of the README
skips this folder (``tests/test_course.py`` runs the grader on the solutions and lessons).

Each test declares the notebook (module-level ``pytestmark``) and the exercise it grades with
its points and the library's reference answer:
``@pytest.mark.exercise("bellman_target", points=2, reference="dlo_course.ddpg.bellman_target")``
(several tests of one exercise share its points: partial credit). It receives the exercise
through the ``student`` fixture (:class:`Student`): ``student.run(probe, *args)`` runs
``probe(student_object, *args)`` in the grading sandbox
(:class:`dlo_course.grading.sandbox.Sandbox`: a forked child process with time, memory and
file-system limits, in a scratch folder, which
runs only the notebook's setup cells and its exercise cells up to that one) and returns what
the probe returns, as plain data. The test then compares that data, in the grader's own
process, with the same probe run on the reference, never the source text. So the student's
code can neither see nor change the checks: patching torch, numpy, pytest or the grader,
writing outside the scratch folder, a crash or an endless loop costs only that exercise
(``DLO_COURSE_GRADING_TIMEOUT`` seconds per probe, 60 by default;
``DLO_COURSE_GRADING_MEMORY_MB`` of memory, 3072). An exercise cell that uses the library
(which holds the reference answers) is rejected before it runs
(:func:`dlo_course.grading.delegation.delegation_problems`), and the reference raises if the answer
reaches it anyway.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

GRADING_DIR = Path(__file__).resolve().parent
REPO_ROOT = GRADING_DIR.parents[1]
DEFAULT_TIMEOUT = float(os.environ.get("DLO_COURSE_GRADING_TIMEOUT", 60))  # s per exercise
_GRADES: dict[str, dict] = {}  # test node id -> notebook, exercise, points, outcome, earned
AWAITING_REVIEW = "awaiting review"  # the outcome of a written answer whose points are pending


def pytest_addoption(parser):
    group = parser.getgroup("dlo-course grading")
    group.addoption("--notebooks", default=None, metavar="DIR",
                    help="folder of notebooks to grade (default: lessons/)")
    group.addoption("--grades-json", default=None, metavar="FILE",
                    help="also write the points per exercise to FILE as JSON")


def _targeted(config) -> bool:
    """Was this folder (or one of its files) named on the command line, or --notebooks given?"""
    if any(str(a).startswith("--notebooks") for a in config.invocation_params.args):
        return True
    if config.args_source != pytest.Config.ArgsSource.ARGS:
        return False  # testpaths: the whole suite, not the grader
    for arg in config.args:
        path = Path(str(arg).split("::")[0])
        if not path.is_absolute():
            path = Path(config.invocation_params.dir) / path
        path = path.resolve()
        if path == GRADING_DIR or GRADING_DIR in path.parents:
            return True
    return False


def pytest_ignore_collect(collection_path, config):
    path = Path(collection_path).resolve()
    if (path == GRADING_DIR or GRADING_DIR in path.parents) and not _targeted(config):
        return True
    return None


def pytest_configure(config):
    config.addinivalue_line("markers", "exercise(name, points): the exercise a grading test "
                                       "grades and the points it is worth")
    config.addinivalue_line("markers", "notebook(stem): the notebook the exercises live in")
    if not config.pluginmanager.hasplugin("timeout"):
        config.addinivalue_line("markers", "timeout(seconds): needs pytest-timeout")


def notebooks_dir(config) -> Path:
    value = config.getoption("notebooks", default=None)
    if value is None:
        return REPO_ROOT / "lessons"
    path = Path(value)
    if not path.is_absolute():
        path = Path(config.invocation_params.dir) / path
    return path


def _markers(item):
    return item.get_closest_marker("exercise"), item.get_closest_marker("notebook")


def pytest_collection_modifyitems(config, items):
    for item in items:
        exercise, notebook = _markers(item)
        if exercise is not None and item.get_closest_marker("timeout") is None:
            # the sandbox enforces DEFAULT_TIMEOUT per probe; this is the backstop (the
            # first test also waits for the sandbox to start)
            item.add_marker(pytest.mark.timeout(2 * DEFAULT_TIMEOUT + 180))


def pytest_collection_finish(session):
    # session.items: what will run, after -k / -m deselection.
    for item in session.items:
        exercise, notebook = _markers(item)
        if exercise is None or notebook is None:
            continue
        _GRADES[item.nodeid] = {
            "notebook": notebook.args[0], "exercise": exercise.args[0],
            "points": exercise.kwargs.get("points", 1), "outcome": "not run", "earned": 0}


def pytest_runtest_logreport(report):
    # Called for setup, call and teardown: any failure loses the points; a passed call wins
    # them unless its teardown fails afterwards.
    record = _GRADES.get(report.nodeid)
    if record is None:
        return
    if report.failed:
        # setup: the fixture could not extract the exercise (missing, or its cell fails)
        record["outcome"] = {"call": "failed", "setup": "not loaded"}.get(report.when,
                                                                          "error (teardown)")
        text = str(report.longrepr)
        if "Timeout (>" in text or "longer than its time limit" in text:
            record["outcome"] = "timeout"
        elif "rejected, the answer is not written in the exercise cell" in text:
            record["outcome"] = "delegates"
        elif " (not loaded):" in text:
            record["outcome"] = "not loaded"
        record["earned"] = 0
        if not record.get("message"):  # the first failure says the most
            crash = getattr(report.longrepr, "reprcrash", None)
            record["message"] = crash.message if crash is not None else str(report.longrepr)
    elif report.skipped:
        record["outcome"], record["earned"] = "skipped", 0
    elif report.when == "call" and record["outcome"] == "not run" and record.get("review"):
        # a written answer that is there: its points are the instructor's, not a pattern's
        record["outcome"], record["earned"] = AWAITING_REVIEW, 0
        record["pending"] = record["points"]
    elif report.when == "call" and record["outcome"] == "not run":
        record["outcome"], record["earned"] = "passed", record["points"]


def _grade_items() -> list[dict]:
    # One entry per exercise (a test per exercise; several tests share its points if needed).
    merged: dict[tuple[str, str], dict] = {}
    for record in _GRADES.values():
        key = (record["notebook"], record["exercise"])
        entry = merged.setdefault(key, {**{k: v for k, v in record.items()
                                           if k not in ("pending", "review")},
                                        "earned": 0, "points": 0, "outcomes": []})
        entry["points"] += record["points"]
        entry["earned"] += record["earned"]
        entry["outcomes"].append(record["outcome"])
        if record.get("message") and not entry.get("message"):
            entry["message"] = record["message"]
        for key in ("text", "rubric", "measured"):
            if key in record:
                entry[key] = record[key]
        if "pending" in record:
            entry["pending"] = entry.get("pending", 0) + record["pending"]
    items = []
    for entry in merged.values():
        outcomes = entry.pop("outcomes")
        bad = [o for o in outcomes if o != "passed"]
        entry["outcome"] = bad[0] if bad else "passed"
        items.append(entry)
    return items


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _GRADES:
        return
    from dlo_course.grading.grade import summary_lines

    items = _grade_items()
    terminalreporter.section(f"dlo-course grades: {notebooks_dir(config)}")
    for line in summary_lines(items):
        terminalreporter.write_line(line)
    out = config.getoption("grades_json", default=None)
    if out:
        report = {"notebooks": str(notebooks_dir(config)), "exercises": items,
                  "total": sum(i["earned"] for i in items),
                  "pending": sum(i.get("pending", 0) for i in items),
                  "max_total": sum(i["points"] for i in items)}
        Path(out).write_text(json.dumps(report, indent=1) + "\n")


# ------------------------------------------------------------------------ fixtures

_BOOKS: dict[Path, object] = {}
_SANDBOX = None
_CACHE: dict[tuple, object] = {}


def sandbox():
    """The session's sandbox (:class:`dlo_course.grading.sandbox.Sandbox`), started on first
    use."""
    global _SANDBOX
    if _SANDBOX is None:
        from dlo_course.grading.sandbox import Sandbox

        _SANDBOX = Sandbox(timeout=DEFAULT_TIMEOUT)
    return _SANDBOX


def pytest_unconfigure(config):
    global _SANDBOX
    if _SANDBOX is not None:
        _SANDBOX.close()
        _SANDBOX = None


class Student:
    """One exercise of the student's notebook, graded at arm's length.

    :meth:`run` calls ``probe(student_object, *args)`` in a sandboxed child process and
    returns what the probe returns, as data; the test then checks that data here, against
    references computed in this (clean) process. A probe is a module-level function of the
    test file: it drives the student's function or class on fixed inputs and returns plain
    results (numbers, strings, containers, arrays, tensors). Running the same probe on the
    library's reference gives what to compare with.
    """

    def __init__(self, path: Path, name: str, references: tuple[str, ...]):
        self.path, self.name, self.references = path, name, references

    def run(self, probe, *args):
        import inspect

        from dlo_course.grading.data import encode_data
        from dlo_course.grading.sandbox import SandboxError

        key = (str(self.path), self.name, inspect.getfile(probe), probe.__qualname__,
               json.dumps(encode_data(args)))
        if key not in _CACHE:
            try:
                _CACHE[key] = sandbox().run(self.path, self.name, inspect.getfile(probe),
                                            probe.__qualname__, args, self.references)
            except SandboxError as err:
                _CACHE[key] = {"status": "error", "message": str(err), "output": ""}
        result = _CACHE[key]
        if result["status"] != "ok":
            output = result.get("output", "").strip()
            printed = f"\n--- what the exercise printed ---\n{output[-3000:]}" if output else ""
            pytest.fail(f"{self.name} ({result['status']}):\n{result['message']}{printed}",
                        pytrace=False)
        return result["value"]


    def run_mpi(self, probe, *args, ranks: int = 2):
        """``probe(student_object, *args)`` in ``ranks`` real MPI processes (``mpiexec``),
        each sandboxed like :meth:`run`; returns the list of what it returned, by rank."""
        return _run_mpi(self.path, self.name, probe, args, ranks, self.references)


def _shared_file(key) -> Path | None:
    """Where the graders of one ``course grade`` share a reference run in MPI processes
    (``DLO_COURSE_REFERENCE_CACHE``, set by :func:`dlo_course.grading.grade.grade`), or
    None. The key names the probe, its file's contents and its arguments."""
    import hashlib

    from dlo_course.grading.grade import REFERENCE_CACHE_VARIABLE

    folder = os.environ.get(REFERENCE_CACHE_VARIABLE)
    if not folder:
        return None
    digest = hashlib.sha256(json.dumps(key).encode() + Path(key[3]).read_bytes()).hexdigest()
    return Path(folder) / f"{digest[:24]}.json"


def _shared_reference(key):
    """The reference runs another grader shared (plain data, :mod:`dlo_course.grading.data`:
    it cannot carry code), or None."""
    from dlo_course.grading.data import decode_data

    path = _shared_file(key)
    if path is None or not path.is_file():
        return None
    return [dict(r, value=decode_data(r["value"])) for r in json.loads(path.read_text())]


def _share_reference(key, results) -> None:
    """Leave a reference run that succeeded on every rank for the other students' graders."""
    from dlo_course.grading.data import encode_data

    path = _shared_file(key)
    if path is None or any(r["status"] != "ok" for r in results):
        return
    partial = path.with_name(f"{path.name}.{os.getpid()}")
    partial.write_text(json.dumps([dict(r, value=encode_data(r["value"])) for r in results]))
    partial.replace(path)  # atomic: a grader reading it never sees half a file


def _run_mpi(path, name, probe, args, ranks, references):
    import inspect

    from dlo_course.grading.data import encode_data
    from dlo_course.grading.mpi import run_mpi
    from dlo_course.grading.sandbox import SandboxError

    key = ("mpi", str(path), name, inspect.getfile(probe), probe.__qualname__,
           json.dumps(encode_data(args)), ranks)
    if key not in _CACHE and path is None:
        _CACHE[key] = _shared_reference(key)  # another student's grader may have run it
    if _CACHE.get(key) is None:
        try:
            _CACHE[key] = run_mpi(path, name, inspect.getfile(probe), probe.__qualname__, args,
                                  references, ranks=ranks, timeout=DEFAULT_TIMEOUT)
        except SandboxError as err:
            _CACHE[key] = [{"status": "error", "message": str(err), "output": ""}]
        if path is None:
            _share_reference(key, _CACHE[key])
    values = []
    for rank, result in enumerate(_CACHE[key]):
        if result["status"] != "ok":
            output = result.get("output", "").strip()
            printed = f"\n--- what rank {rank} printed ---\n{output[-3000:]}" if output else ""
            who = name or "the reference"
            pytest.fail(f"{who} (rank {rank}, {result['status']}):\n{result['message']}"
                        f"{printed}", pytrace=False)
        values.append(result["value"])
    return values


@pytest.fixture
def mpi_reference():
    """``mpi_reference(probe, *args, ranks=2)``: ``probe(None, *args)`` in ``ranks`` MPI
    processes (the probe then uses the library), by rank, computed once per session."""
    def run(probe, *args, ranks: int = 2):
        return _run_mpi(None, "", probe, args, ranks, ())

    return run


@pytest.fixture
def data_probe():
    """``data_probe(probe, *args, timeout=None)``: ``probe(None, *args)`` in a sandbox worker
    that runs no cell of the student's notebook, for what a student handed in as data (e.g.
    an actor file's bytes, evaluated again): nothing of theirs runs in the grader's process,
    and no code of theirs runs beside the probe. ``timeout``: seconds (default: an
    exercise's). Fails the test if the worker does not return."""
    def run(probe, *args, timeout: float | None = None):
        import inspect

        from dlo_course.grading.sandbox import SandboxError

        try:
            result = sandbox().run(None, "", inspect.getfile(probe), probe.__qualname__, args,
                                   timeout=timeout)
        except SandboxError as err:
            result = {"status": "error", "message": str(err), "output": ""}
        if result["status"] != "ok":
            output = result.get("output", "").strip()
            printed = f"\n--- what it printed ---\n{output[-3000:]}" if output else ""
            pytest.fail(f"{probe.__name__} ({result['status']}):\n{result['message']}"
                        f"{printed}", pytrace=False)
        return result["value"]

    return run


@pytest.fixture
def grade_record(request) -> dict:
    """The grades' record of this test's exercise: a test may add plain data under
    ``"measured"`` (what the grader measured of a hand-in), which goes into the grades JSON
    and the class CSV. A dict of its own when the test grades no exercise."""
    return _GRADES.get(request.node.nodeid, {})


@pytest.fixture
def notebook_folder(request) -> Path:
    """The folder of the graded notebook (the test's ``notebook`` marker) in the student's
    hand-in, where files handed in beside it are found. Fails the test if the notebook is
    missing."""
    from dlo_course.grading.runner import ExerciseError, find_notebook

    notebook = request.node.get_closest_marker("notebook").args[0]
    try:
        return find_notebook(notebooks_dir(request.config), notebook).parent
    except (ExerciseError, OSError) as err:
        pytest.fail(str(err), pytrace=False)


def load_student(config, notebook: str, name: str, references=()) -> Student:
    """The student's exercise ``name`` of ``notebook``, checked without running it: the cell
    exists and does its own work (no delegation to the library). Fails the test otherwise."""
    from dlo_course.grading.delegation import delegation_message, delegation_problems
    from dlo_course.grading.runner import ExerciseError, ExerciseNotebook, find_notebook

    try:
        path = find_notebook(notebooks_dir(config), notebook)
        if path not in _BOOKS:
            _BOOKS[path] = ExerciseNotebook.from_path(path)
        book = _BOOKS[path]
        source = book.source_of(name)
    except (ExerciseError, ValueError, OSError) as err:
        pytest.fail(str(err), pytrace=False)
    if isinstance(references, str):
        references = (references,)
    problems = delegation_problems(source, book.setup_sources, references)
    if problems:
        pytest.fail(delegation_message(name, problems), pytrace=False)
    return Student(path, name, tuple(references))


@pytest.fixture
def student(request):
    """The graded exercise (the test's ``exercise`` marker) as a :class:`Student`."""
    notebook = request.node.get_closest_marker("notebook").args[0]
    marker = request.node.get_closest_marker("exercise")
    return load_student(request.config, notebook, marker.args[0],
                        marker.kwargs.get("reference", ()))


class WrittenAnswer:
    """A written answer (a Markdown cell) of the student's notebook: its text, never run.

    No pattern gives it points. :meth:`check` fails, with no points, if it is missing or too
    short (:func:`dlo_course.grading.notebooks.written_answer_problem`); otherwise it passes
    and the answer *awaits the instructor's review*: ``record["review"]`` makes the pass earn
    nothing yet, its points pending (:func:`pytest_runtest_logreport`), until the
    instructor's reviews file gives them (:mod:`dlo_course.grading.reviews`). The text, and
    which criteria of its rubric have patterns in it (a hint for the reader, not points), go
    into the grades (``--grades-json``, the class CSV).

    A **choice** answer (``choices``) is structured, so its grade is automatic: it passes,
    with its points, when it names exactly one option's label, e.g. ``(b)``
    (:func:`dlo_course.grading.notebooks.chosen_options`), and fails listing the options
    otherwise."""

    def __init__(self, name: str, text: str, min_words: int, rubric=(), record=None,
                 choices=()):
        self.name, self.text, self.min_words = name, text, min_words
        self.rubric, self.record, self.choices = list(rubric), record, list(choices)

    def check(self) -> None:
        from dlo_course.grading.notebooks import (choices_line, chosen_options, rubric_met,
                                                  written_answer_problem)

        if self.record is not None and self.rubric:
            self.record["rubric"] = [{"criterion": item["criterion"], "patterns_found": found}
                                     for item, found in zip(self.rubric,
                                                            rubric_met(self.text, self.rubric))]
        problem = written_answer_problem(self.text, self.min_words)
        if problem:
            pytest.fail(f"{self.name}: {problem}", pytrace=False)
        if self.choices:
            if self.record is not None:
                self.record["choices"] = self.choices
            chosen = chosen_options(self.text, self.choices)
            if len(chosen) != 1:
                found = ", ".join(f"({label})" for label in chosen) or "none"
                pytest.fail(f"{self.name}: name exactly one of the options by its letter in "
                            f"brackets, e.g. (b), then say why (found: {found}). "
                            f"{choices_line(self.choices)}", pytrace=False)
            return  # a choice among stated options: its points are automatic
        if self.record is not None:
            self.record["review"] = True


@pytest.fixture
def written_answer(request):
    """The graded written answer (the test's ``exercise`` marker) as a :class:`WrittenAnswer`;
    its text is recorded with the grades, even when it is too short. Its rubric and least
    number of words (and a choice's options) are the course's solution's when ``solutions/``
    has the notebook (a student who edits or drops the cell's metadata cannot change them),
    else the cell's own."""
    from dlo_course.grading.notebooks import SOLUTIONS_DIR, written_answers
    from dlo_course.grading.runner import ExerciseError, find_notebook

    notebook = request.node.get_closest_marker("notebook").args[0]
    name = request.node.get_closest_marker("exercise").args[0]
    try:
        answers = written_answers(find_notebook(notebooks_dir(request.config), notebook))
    except (ExerciseError, ValueError, OSError) as err:
        pytest.fail(str(err), pytrace=False)
    if name not in answers:
        pytest.fail(f"{notebook}.ipynb: no written-answer cell for {name!r} (keep the cell "
                    f"and its first line <!-- answer: {name} ... -->)", pytrace=False)
    rubric, min_words = answers[name]["rubric"], answers[name]["min_words"]
    choices = answers[name]["choices"]
    solution = SOLUTIONS_DIR / f"{notebook}.ipynb"
    if solution.is_file():
        try:
            course = written_answers(solution).get(name, {})
        except ValueError as err:
            pytest.fail(str(err), pytrace=False)
        rubric, min_words = course.get("rubric", rubric), course.get("min_words", min_words)
        choices = course.get("choices", choices)
    record = _GRADES.get(request.node.nodeid)
    if record is not None:
        record["text"] = answers[name]["text"]
    return WrittenAnswer(name, answers[name]["text"], min_words, rubric, record, choices)
