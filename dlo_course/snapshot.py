"""An exact snapshot of the simulated world, by ``fork``: the reset PyBullet cannot save.

Table I's episodes "with reinitialisation" all start from the same state: the world rebuilt
and left to settle for 20 + m physics steps (the authors' reset), about as long as the episode
itself. PyBullet cannot save that state: ``saveState``/``restoreState`` skip soft bodies, and
``resetMeshData`` restores the rod's node positions but not their velocities (docs/design.md,
"Evaluation speed"). The operating system can: ``os.fork()`` copies the whole process, the
physics engine's memory included, bit for bit. So the world is rebuilt and settled once, and
every episode runs in a forked child of that process, which sends back what it measured and
exits; the parent's world stays untouched for the next episode. The result is the same as
rebuilding before every episode (``tests/test_evaluation.py`` compares them bit for bit), at
the cost of a fork (milliseconds) instead of a rebuild and its settling (seconds).

Where ``fork`` is missing (Windows) or unsafe (the PyBullet GUI, whose window belongs to the
parent), the callers fall back to rebuilding; ``DLO_COURSE_NO_FORK=1`` forces that fallback.
"""

from __future__ import annotations

import os
import pickle
import sys
import traceback
from typing import Any, Callable

NO_FORK_VARIABLE = "DLO_COURSE_NO_FORK"
"""Set this environment variable to 1 to rebuild the world instead of forking it."""


def fork_available() -> bool:
    """True where :func:`run_in_fork` can be used: a POSIX system, not disabled by
    ``DLO_COURSE_NO_FORK=1``."""
    return hasattr(os, "fork") and os.environ.get(NO_FORK_VARIABLE, "0") in ("", "0")


def fork_flushed() -> int:
    """``os.fork()`` after flushing Python's stdout and stderr, so that nothing the parent had
    buffered is written twice (once by each process). Returns the child's pid, 0 in the
    child."""
    sys.stdout.flush()
    sys.stderr.flush()
    return os.fork()


def run_in_fork(fn: Callable[[], Any]) -> Any:
    """``fn()`` run in a forked copy of this process; its (picklable) return value.

    Nothing ``fn`` changes survives in this process: the simulator, the networks, the
    random generators all stay as they were before the call. An exception in the child is
    raised here as a ``RuntimeError`` with the child's traceback.

    The child never returns into the caller's code: it leaves with ``os._exit``, which skips
    the interpreter's exit handlers (MPI's finalisation among them, which belongs to the
    parent). It must not use MPI either: every collective call stays in the parent.
    """
    read_end, write_end = os.pipe()
    pid = fork_flushed()
    if pid == 0:  # the child
        status = 0
        try:
            os.close(read_end)
            try:
                payload = pickle.dumps((True, fn()))
            except BaseException:  # noqa: BLE001 - everything goes back to the parent
                payload = pickle.dumps((False, traceback.format_exc()))
                status = 1
            with os.fdopen(write_end, "wb") as pipe:
                pipe.write(payload)
        finally:
            os._exit(status)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as pipe:
        payload = pipe.read()
    _, wait_status = os.waitpid(pid, 0)
    if not payload:
        raise RuntimeError(f"the forked episode died without an answer (wait status "
                           f"{wait_status}); set {NO_FORK_VARIABLE}=1 to rebuild instead")
    ok, value = pickle.loads(payload)
    if not ok:
        raise RuntimeError(f"the forked episode failed:\n{value}")
    return value
