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

Forking a process that has used threads is the classic trap: the child has only the thread
that called ``fork``. PyTorch's CPU kernels run on GNU OpenMP's thread pool, which is not
fork-safe: once the parent has run one parallel region (loading an actor initialises its
256 x 256 layers in one), the child's next parallel region waits forever for pool threads
that were not copied. So the child sets torch to one thread before it runs anything
(:func:`run_in_fork`): a region of one thread never touches the pool. The evaluation also
holds the parent to one thread while it plays episodes (:func:`torch_threads`), so a forked
episode and a rebuilt one compute with the same thread count, bit for bit; for a batch of one
observation, more threads would not be faster anyway.

A child that still stops answering becomes an error, never a silent wait: where the
operating system tells a process's CPU time (``/proc``, Linux), a child that has used no CPU
for :data:`STALL_SECONDS` is deadlocked (a simulated episode always computes); anywhere, one
that has not answered in ``DLO_COURSE_FORK_TIMEOUT`` seconds (:data:`TIMEOUT_VARIABLE`,
default :data:`DEFAULT_TIMEOUT`) is killed. Both errors name ``DLO_COURSE_NO_FORK=1``.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import signal
import sys
import time
import traceback
from typing import Any, Callable, Iterator

NO_FORK_VARIABLE = "DLO_COURSE_NO_FORK"
"""Set this environment variable to 1 to rebuild the world instead of forking it."""
TIMEOUT_VARIABLE = "DLO_COURSE_FORK_TIMEOUT"
"""Seconds a forked episode may take before it is killed as hung (default
:data:`DEFAULT_TIMEOUT`)."""
DEFAULT_TIMEOUT = 1800.0
"""Half an hour: a Table I episode takes seconds, the longest (300 actions at the paper's
sub-steps, on a slow laptop) a few minutes."""
STALL_SECONDS = 30.0
"""A child that has used no CPU time for this long, while its parent waits for it, is taken
for deadlocked (a simulated episode computes all the time; even 32 processes sharing one core
each get a second of CPU in 30)."""


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


@contextlib.contextmanager
def torch_threads(n: int = 1) -> Iterator[None]:
    """Within the block, torch computes on ``n`` intra-op threads; the old count comes back
    after it. Does nothing when torch has not been imported (a controller without networks).

    The evaluation holds one thread around its episodes, forked or rebuilt: a forked child
    must compute on one (:func:`run_in_fork`), so the rebuilt episodes do too, and both give
    the same bits whatever the machine's core count."""
    torch = sys.modules.get("torch")
    if torch is None:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _one_thread_in_child() -> None:
    # The parent's OpenMP pool was not copied by fork: a parallel region of more than one
    # thread would wait for it forever. A region of one thread never looks at the pool.
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def _cpu_seconds(pid: int) -> float | None:
    """The CPU time (user + system) the process ``pid`` has used, or ``None`` where the
    system does not tell (no ``/proc``)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
    except (OSError, IndexError):
        return None
    # after the name: state is field 3, utime and stime fields 14 and 15 (proc(5))
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _hung(pid: int, why: str) -> RuntimeError:
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return RuntimeError(f"the forked episode {why}: it was killed. Set {NO_FORK_VARIABLE}=1 to "
                        f"rebuild the world before every episode instead of forking it (slower, "
                        f"same results), and please report this with your platform and "
                        f"`python -c 'import torch; print(torch.__config__.parallel_info())'`")


def _read_answer(pid: int, read_end: int, timeout: float, stall: float) -> bytes:
    """Everything the child ``pid`` writes to ``read_end`` until it closes it; raises
    ``RuntimeError`` (and kills the child) if it exceeds ``timeout`` seconds or uses no CPU
    for ``stall`` seconds."""
    chunks = []
    start = last_progress = time.monotonic()
    last_cpu = _cpu_seconds(pid)
    while True:
        readable, _, _ = select.select([read_end], [], [], 1.0)
        now = time.monotonic()
        if readable:
            chunk = os.read(read_end, 1 << 20)
            if not chunk:  # the child closed its end: the whole answer is here
                return b"".join(chunks)
            chunks.append(chunk)
            last_progress = now
            continue
        if now - start > timeout:
            raise _hung(pid, f"did not answer in {timeout:.0f} s ({TIMEOUT_VARIABLE})")
        cpu = _cpu_seconds(pid)
        if cpu is None or last_cpu is None or cpu > last_cpu:
            last_cpu, last_progress = cpu, now
        elif now - last_progress > stall:
            raise _hung(pid, f"used no CPU for {stall:.0f} s without answering (deadlocked)")


def run_in_fork(fn: Callable[[], Any], timeout: float | None = None,
                stall: float = STALL_SECONDS) -> Any:
    """``fn()`` run in a forked copy of this process; its (picklable) return value.

    Nothing ``fn`` changes survives in this process: the simulator, the networks, the
    random generators all stay as they were before the call. An exception in the child is
    raised here as a ``RuntimeError`` with the child's traceback; so is a child that hangs
    (see the module's docstring), after it is killed.

    In the child torch computes on one thread (the parent's OpenMP pool does not survive a
    fork). The child never returns into the caller's code: it leaves with ``os._exit``, which
    skips the interpreter's exit handlers (MPI's finalisation among them, which belongs to the
    parent). It must not use MPI either: every collective call stays in the parent.

    Args:
        fn: what the child runs.
        timeout: seconds before the child is killed as hung (``None``: the
            ``DLO_COURSE_FORK_TIMEOUT`` variable, else :data:`DEFAULT_TIMEOUT`).
        stall: seconds without CPU use before the child is taken for deadlocked (Linux).
    """
    if timeout is None:
        timeout = float(os.environ.get(TIMEOUT_VARIABLE) or DEFAULT_TIMEOUT)
    read_end, write_end = os.pipe()
    pid = fork_flushed()
    if pid == 0:  # the child
        status = 0
        try:
            os.close(read_end)
            try:
                _one_thread_in_child()
                payload = pickle.dumps((True, fn()))
            except BaseException:  # noqa: BLE001 - everything goes back to the parent
                payload = pickle.dumps((False, traceback.format_exc()))
                status = 1
            with os.fdopen(write_end, "wb") as pipe:
                pipe.write(payload)
        finally:
            os._exit(status)
    os.close(write_end)
    try:
        payload = _read_answer(pid, read_end, timeout, stall)
    finally:
        os.close(read_end)
    _, wait_status = os.waitpid(pid, 0)
    if not payload:
        raise RuntimeError(f"the forked episode died without an answer (wait status "
                           f"{wait_status}); set {NO_FORK_VARIABLE}=1 to rebuild instead")
    ok, value = pickle.loads(payload)
    if not ok:
        raise RuntimeError(f"the forked episode failed:\n{value}")
    return value
