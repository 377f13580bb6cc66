"""Shared fixtures, and the fast lane's marks. Simulator tests are sized for 2 cores: a handful
of actions each.

The fast lane, ``python -m pytest -m "not slow" -n 2``, checks the library in about a minute;
CI runs every test. ``slow`` marks a test that executes notebooks, grades, starts mpiexec,
trains, or simulates for more than a few seconds: on the test itself, with ``pytestmark`` on a
whole file, or here for the files listed in :data:`SLOW_FILES` and every ``mpi`` test.
"""

from __future__ import annotations

import numpy as np
import pytest

import dlo_course  # noqa: F401  (registers DLOShape-v0)
from dlo_course.env import DLOShapeEnv

SLOW_FILES = {
    "test_course.py": "executes the 16 solution notebooks and grades them",
    "test_grading_attacks.py": "grades attacks in the sandbox",
    "test_mutations.py": "six mutation rounds, each a grading of every lesson in a pytest subprocess",
}
"""Files whose every test is slow, by name (marked here: they are being moved with the
grader, so they are not edited for it now)."""


def pytest_addoption(parser):
    parser.addoption("--mutants-of", default="", metavar="LESSON",
                     help="tests/test_mutations.py grades only the lessons whose notebook "
                          "name contains LESSON (e.g. 04_ddpg)")


SHARED_ON_ONE_WORKER = ("trained_hand_in",)
"""Session fixtures that take minutes to build: every test that uses one runs on the same
xdist worker (an ``xdist_group`` named after the fixture), which builds it once."""


@pytest.hookimpl(tryfirst=True)  # before xdist's loadgroup reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in SLOW_FILES or item.get_closest_marker("mpi"):
            item.add_marker(pytest.mark.slow)
        for name in SHARED_ON_ONE_WORKER:
            if name in item.fixturenames:
                item.add_marker(pytest.mark.xdist_group(name))


@pytest.fixture
def far_goals():
    """Two goal sets for 4 nodes, far from the rod, so an episode never terminates early."""
    rng = np.random.default_rng(0)
    return np.array([[1.0, 0.3, 0.5], [1.0, 0.3, 0.7], [1.0, 0.3, 0.9], [1.0, 0.3, 1.1]]) \
        + rng.normal(0, 0.01, size=(3, 4, 3))


@pytest.fixture
def make_env():
    """Build environments and close them at the end of the test."""
    envs = []

    def _make(**kwargs):
        env = DLOShapeEnv(**kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


@pytest.fixture(scope="session")
def trained_hand_in(tmp_path_factory):
    """(folder, report): lesson 13's hand-in of an agent that learned, written by the library
    (one evaluation of the graded protocol): the shipped 2-node actor, from a run directory
    with its run's configuration and learning curve. The grader refuses it as a shipped
    actor, unless the installation does not ship it (:func:`data_without_the_2_node_agent`)."""
    import shutil

    from dlo_course.paths import AGENTS_DIR
    from dlo_course.submission import SUBMISSION_DIR, write_submission

    root = tmp_path_factory.mktemp("trained_hand_in")
    run = root / "run"
    run.mkdir()
    for name in ("actor.pt", "config.json", "progress.csv"):
        shutil.copyfile(AGENTS_DIR / "nodes2" / name, run / name)
    folder = root / SUBMISSION_DIR
    return folder, write_submission(run, folder)


@pytest.fixture(scope="session")
def data_without_the_2_node_agent(tmp_path_factory):
    """A copy of the course's data folder without the 2-node agent, for ``DLO_COURSE_DATA``:
    an installation in which the shipped 2-node actor is an agent the student trained (the
    grader's shipped actors are those of its data folder)."""
    import shutil

    from dlo_course.paths import DATA_DIR

    root = tmp_path_factory.mktemp("installation") / "data"
    shutil.copytree(DATA_DIR, root, ignore=shutil.ignore_patterns("nodes2"))
    return root


@pytest.fixture(scope="session")
def trained_pendulum_actor(tmp_path_factory):
    """Lesson 04's hand-in: a Pendulum actor trained by lesson 04's training with the library's
    pieces (seed 0, about 20 s of CPU on one thread), saved where the grader reads it."""
    import torch

    from dlo_course import pendulum
    from dlo_course.ddpg import save_network

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        agent, _ = pendulum.train_pendulum()
    finally:
        torch.set_num_threads(threads)
    path = tmp_path_factory.mktemp("pendulum") / pendulum.ACTOR_FILE
    save_network(agent.actor, path)
    return path
