"""The environment a user's shell has: what the tests that run as a user start their processes in.

The grader and the trainer pin torch to one thread, and MPI ranks get one core each; a student
on a laptop has none of that. So these processes get the test's environment without the
thread variables and without the course's own variables, with torch left at its default
thread count; on a one-core machine, two threads are forced, so that what only goes wrong
with several threads (a fork after OpenMP, dlo_course/snapshot.py) goes wrong here too.
"""

from __future__ import annotations

import os

THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
COURSE_PREFIX = "DLO_COURSE_"


def user_environment(**extra: str) -> dict[str, str]:
    """``os.environ`` as a user's fresh shell would have it (see the module), plus ``extra``
    and a non-interactive matplotlib backend (a headless machine has no screen)."""
    env = {k: v for k, v in os.environ.items() if not _set_by_tests(k)}
    if (os.cpu_count() or 1) < 2:
        env["OMP_NUM_THREADS"] = "2"
    env["MPLBACKEND"] = "Agg"
    env.update(extra)
    return env


def use_user_environment(monkeypatch, **extra: str) -> None:
    """Make ``os.environ`` :func:`user_environment` for one test (``monkeypatch`` undoes it),
    for what starts its processes from ``os.environ`` itself, as a Jupyter kernel does."""
    wanted = user_environment(**extra)
    for name in [k for k in os.environ if k not in wanted]:
        monkeypatch.delenv(name)
    for name, value in wanted.items():
        monkeypatch.setenv(name, value)


def _set_by_tests(name: str) -> bool:
    return name in THREAD_VARIABLES or name.startswith(COURSE_PREFIX)

