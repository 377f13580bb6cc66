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
    env = {k: v for k, v in os.environ.items()
           if k not in THREAD_VARIABLES and not k.startswith(COURSE_PREFIX)}
    if (os.cpu_count() or 1) < 2:
        env["OMP_NUM_THREADS"] = "2"
    env["MPLBACKEND"] = "Agg"
    env.update(extra)
    return env

