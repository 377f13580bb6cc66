"""The student bundle (``dlo-course course release --student DIR``): the repository without
the answers, and the grader's own answers replaced by their recorded results.

The bundle keeps the grader (``tests/grading``) so that students can grade themselves. Its
references are the library's, which the bundle ships anyway, except for the few exercises the
library has no reference for: their answers are the grader's own (``tests/grading/answers.py``,
left out of the bundle), and :func:`answer_result` reads instead what each answer's probe
returned at release (``answers.json``, written by :func:`record_answers`).

A recorded result is an expected output for fixed inputs, which an answer could copy (return
the recorded value when it recognises the probe's inputs), in the bundle and, as the grader's
``answers.py`` gives the same value, in the instructor's grading too. So an exercise is checked
without one where that is cheap: ``discounted_return`` on rewards drawn afresh at every
grading, against the recursion that defines it (the return of no reward is 0, and that of
``r_k, r_k+1, ...`` is ``r_k`` plus gamma times that of ``r_k+1, ...``, on every suffix),
which pins it down with no answer in the bundle; and the done flag that lesson 2's
``RingBuffer.add`` stores from a step's ``terminated`` and ``truncated`` (once an exercise of
its own, whose four possible inputs made its four recorded values the answer) against the
library's ``ReplayBuffer`` fed what the trainer stores, on flags drawn afresh at every grading.
The others keep a recorded result, because every check that pins them down is their answer,
written in the bundle's grader:

* ``q_iteration_sweep``: on fresh inputs, the only exact check recomputes the sweep (the
  library's ``bellman_target`` on ``max_a' Q(s', a')``), which is the whole exercise; its
  properties (a done transition gives its reward, gamma = 0 the rewards) leave the greedy
  maximum over the next state's actions unchecked;
* ``pack_gradients``: the expected vector of a fresh module is its gradients concatenated in
  parameter order, zeros for a missing one, which is the answer itself (the library packs
  only inside ``dlo_course.mpi.allreduce_gradients``, which needs MPI and returns nothing
  packed).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

from dlo_course.grading.data import decode_data, encode_data
from dlo_course.grading.notebooks import (GRADING_TESTS_DIR, SOLUTION_BEGIN, SOLUTION_END,
                                          SOLUTIONS_DIR, release)
from dlo_course.paths import REPO_ROOT

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
