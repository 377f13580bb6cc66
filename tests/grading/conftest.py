"""Autograding of the lesson notebooks.

Run ``python -m pytest tests/grading`` to grade ``lessons/`` (where every exercise fails until
it is solved), or ``python -m pytest tests/grading --notebooks DIR`` to grade the notebooks in
``DIR`` (a student's folder, or ``solutions``). ``--grades-json FILE`` also writes the points as
JSON (``dlo-course course grade`` uses it).

These tests are collected only when targeted: the plain ``python -m pytest`` of the README
skips this folder (``tests/test_course.py`` runs the grader on the solutions and lessons).

Each test declares the notebook (module-level ``pytestmark``) and the exercise it grades with
its points: ``@pytest.mark.exercise("bellman_target", points=2)``. It receives the student's
function through the ``exercise`` fixture: the grader runs only the notebook's setup cells and
its exercise cells up to that one, in a fresh namespace
(:class:`dlo_course.course.ExerciseNotebook`), and compares behaviour with the library's
reference implementation on fixed inputs, never the source text. A crash or an endless loop
costs only that exercise: every test has a timeout (pytest-timeout; 60 s, or
``DLO_COURSE_GRADING_TIMEOUT`` seconds).
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
            item.add_marker(pytest.mark.timeout(DEFAULT_TIMEOUT))


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
        if "Timeout (>" in str(report.longrepr):
            record["outcome"] = "timeout"
        record["earned"] = 0
    elif report.skipped:
        record["outcome"], record["earned"] = "skipped", 0
    elif report.when == "call" and record["outcome"] == "not run":
        record["outcome"], record["earned"] = "passed", record["points"]


def _grade_items() -> list[dict]:
    # One entry per exercise (a test per exercise; several tests share its points if needed).
    merged: dict[tuple[str, str], dict] = {}
    for record in _GRADES.values():
        key = (record["notebook"], record["exercise"])
        entry = merged.setdefault(key, {**record, "earned": 0, "points": 0, "outcomes": []})
        entry["points"] += record["points"]
        entry["earned"] += record["earned"]
        entry["outcomes"].append(record["outcome"])
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
    from dlo_course.course import summary_lines

    items = _grade_items()
    terminalreporter.section(f"dlo-course grades: {notebooks_dir(config)}")
    for line in summary_lines(items):
        terminalreporter.write_line(line)
    out = config.getoption("grades_json", default=None)
    if out:
        report = {"notebooks": str(notebooks_dir(config)), "exercises": items,
                  "total": sum(i["earned"] for i in items),
                  "max_total": sum(i["points"] for i in items)}
        Path(out).write_text(json.dumps(report, indent=1) + "\n")


# ------------------------------------------------------------------------ fixtures

_BOOKS: dict[Path, object] = {}


def load_exercise(config, notebook: str, name: str):
    """The student's ``name`` from ``notebook``; fails the test (only) if it cannot be had."""
    from dlo_course.course import ExerciseError, ExerciseNotebook, find_notebook

    # Setup cells may plot or read the budget: headless, and small.
    os.environ.setdefault("MPLBACKEND", "Agg")
    os.environ.setdefault("DLO_COURSE_FAST", "1")
    try:
        path = find_notebook(notebooks_dir(config), notebook)
        if path not in _BOOKS:
            _BOOKS[path] = ExerciseNotebook.from_path(path)
        return _BOOKS[path].load(name)
    except ExerciseError as err:
        pytest.fail(str(err), pytrace=False)


@pytest.fixture
def exercise(request):
    """The object the graded exercise cell defines (the test's ``exercise`` marker)."""
    notebook = request.node.get_closest_marker("notebook").args[0]
    name = request.node.get_closest_marker("exercise").args[0]
    return load_exercise(request.config, notebook, name)
