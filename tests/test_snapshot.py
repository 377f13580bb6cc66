"""The forked snapshot (dlo_course/snapshot.py): isolation, errors, and no deadlock after threads.

The deadlock these tests guard against: torch's CPU kernels run on GNU OpenMP's thread pool,
which a fork does not copy. A parent that has run one parallel region, then forks a child that
runs another, leaves the child waiting forever for threads that do not exist. On Intel CPUs the
actor's own forward pass (MKL's threaded sgemv) was enough; on others an element-wise kernel
over a few million floats is, which is what these tests use, so they bite on every CPU.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

from dlo_course import snapshot
from user_env import user_environment

# A fresh interpreter, as a user's script: torch at two threads or more, a parallel region in
# the parent, then one in a forked child. Before the fix it hung (no answer in 60 s).
PARALLEL_REGION_THEN_FORK = textwrap.dedent("""
    import torch
    torch.set_num_threads(max(2, torch.get_num_threads()))
    from dlo_course.snapshot import run_in_fork
    x = torch.rand(4_000_000)
    float((x * 2).sum())            # the parent's OpenMP pool is now started
    answer = run_in_fork(lambda: float((x * 3).sum()) / float((x * 2).sum()))
    print("threads", torch.get_num_threads(), "answer", round(answer, 3))
""")


def test_a_forked_child_computes_after_the_parent_used_threads():
    proc = subprocess.run([sys.executable, "-c", PARALLEL_REGION_THEN_FORK], timeout=60,
                          capture_output=True, text=True, env=user_environment())
    assert proc.returncode == 0, proc.stderr[-2000:]
    threads, answer = proc.stdout.split()[1], proc.stdout.split()[3]
    assert int(threads) >= 2  # the parent kept its threads: only the child runs on one
    assert float(answer) == 1.5


def test_run_in_fork_isolates_and_reports_failures(monkeypatch):
    state = {"n": 1}

    def change_and_return():
        state["n"] = 99
        return np.arange(3)

    np.testing.assert_array_equal(snapshot.run_in_fork(change_and_return), [0, 1, 2])
    assert state["n"] == 1  # the child's change stayed in the child
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):
        snapshot.run_in_fork(lambda: 1 / 0)
    monkeypatch.setenv(snapshot.NO_FORK_VARIABLE, "1")
    assert not snapshot.fork_available()
    monkeypatch.setenv(snapshot.NO_FORK_VARIABLE, "0")
    assert snapshot.fork_available()


def test_a_large_answer_comes_back_whole():
    # bigger than a pipe's buffer: the parent must read while the child writes
    value = snapshot.run_in_fork(lambda: np.arange(2_000_000, dtype=np.float64))
    np.testing.assert_array_equal(value, np.arange(2_000_000, dtype=np.float64))


@pytest.mark.skipif(not os.path.exists(f"/proc/{os.getpid()}/stat"), reason="needs /proc")
def test_a_deadlocked_child_is_killed_with_an_error_naming_the_fallback():
    def deadlock():
        lock = threading.Lock()
        lock.acquire()
        lock.acquire()  # sleeps forever, using no CPU: what a child stuck in libgomp does

    with pytest.raises(RuntimeError, match=f"no CPU.*{snapshot.NO_FORK_VARIABLE}=1"):
        snapshot.run_in_fork(deadlock, timeout=120, stall=2)


def test_a_child_past_its_timeout_is_killed(monkeypatch):
    def spin():
        while True:
            pass

    monkeypatch.setenv(snapshot.TIMEOUT_VARIABLE, "2")
    with pytest.raises(RuntimeError, match=f"did not answer in 2 s.*{snapshot.NO_FORK_VARIABLE}"):
        snapshot.run_in_fork(spin)


def test_torch_threads_holds_and_restores_the_count():
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(3)
    try:
        with snapshot.torch_threads(1):
            assert torch.get_num_threads() == 1
        assert torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(before)
