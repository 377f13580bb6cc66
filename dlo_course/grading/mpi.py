"""Sandboxed MPI ranks: an exercise written with mpi4py is graded in real MPI processes.

The grader starts ``mpiexec -n N python -c "...mpi_sandbox_rank()" REQUEST`` in a fresh
folder (:func:`run_mpi`): every rank initialises MPI and exchanges a few messages of every
size class first (so the connections and shared-memory segments MPI uses exist before the
doors close), then fences itself in as a sandbox worker does
(:func:`dlo_course.grading.fence.restrict_worker`, its own scratch folder ``rank<r>/``), runs
the probe on the student's object and writes its result as data. The grader, which never
imports mpi4py, reads the N results. A rank that hangs (a student's collective that the
other rank never joins) is killed with the whole launcher at the time limit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterable

from dlo_course.grading.data import encode_data
from dlo_course.grading.sandbox import (SANDBOX_MEMORY_MB, SandboxError, preload, read_result,
                                        run_worker)


def mpi_sandbox_rank() -> None:
    """One rank of :func:`run_mpi` (``sys.argv[1]``: the request file)."""
    request = json.loads(Path(sys.argv[1]).read_text())
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    rank = comm.Get_rank()
    scratch = os.path.join(request["root"], f"rank{rank}")
    os.makedirs(scratch, exist_ok=True)
    log = os.open(os.path.join(scratch, "output.txt"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
                  0o600)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    preload()
    import numpy as np

    for n in (1, 1024, 1 << 18):  # eager and rendezvous messages, before the restrictions
        buf = np.ones(n, np.float32)
        comm.Allreduce(MPI.IN_PLACE, buf)
        comm.Bcast(buf, root=0)
    comm.allgather(rank)
    comm.Barrier()
    result_fd = os.open(os.path.join(request["root"], f"rank{rank}.json"),
                        os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    run_worker(dict(request, scratch=scratch), result_fd)
    sys.stdout.flush()
    sys.stderr.flush()


def find_mpiexec() -> Path | None:
    """The ``mpiexec`` beside this Python (the mpich wheel's), or the first on the PATH."""
    import shutil

    beside = Path(sys.executable).parent / "mpiexec"
    if beside.is_file():
        return beside
    found = shutil.which("mpiexec")
    return Path(found) if found else None


def run_mpi(notebook: str | Path | None, exercise: str, probe_file: str | Path, probe: str,
            args: tuple = (), references: Iterable[str] = (), ranks: int = 2,
            timeout: float = 60.0, memory_mb: float = SANDBOX_MEMORY_MB,
            startup: float = 120.0) -> list[dict[str, Any]]:
    """Run ``probe(obj, *args)`` in ``ranks`` sandboxed MPI processes, ``obj`` being what the
    exercise cell of ``notebook`` defines (``notebook=None``: ``obj`` is None, a reference
    run of a probe that then uses the library).

    Returns:
        One dict per rank, as :meth:`Sandbox.run`: ``status``, ``value``, ``message``,
        ``output``.

    Raises:
        SandboxError: no ``mpiexec`` (``pip install mpich``, the ``mpi`` extra).
    """
    import shutil
    import signal

    mpiexec = find_mpiexec()
    if mpiexec is None:
        raise SandboxError("grading this exercise needs mpiexec: pip install mpich mpi4py")
    with tempfile.TemporaryDirectory(prefix="dlo-grading-mpi-") as tmp:
        root = Path(tmp).resolve()
        copy_path = None
        if notebook is not None:
            copy_path = root / Path(notebook).name
            copy_path.write_bytes(Path(notebook).read_bytes())
        request = {"root": str(root), "notebook": None if copy_path is None else str(copy_path),
                   "exercise": exercise, "probe_file": str(Path(probe_file).resolve()),
                   "probe": probe, "args": encode_data(tuple(args)),
                   "references": list(references), "timeout": float(timeout),
                   "memory_mb": float(memory_mb)}
        (root / "request.json").write_text(json.dumps(request))
        env = {k: v for k, v in os.environ.items()
               if not k.startswith(("PMI", "PMIX", "MPI", "OMPI", "HYDRA"))}
        env.update(MPLBACKEND="Agg", DLO_COURSE_FAST="1", OMP_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="1",
                   MPLCONFIGDIR=str(root / "mpl"), DLO_COURSE_OUTPUT=str(root / "output"))
        env.pop("PYTHONSTARTUP", None)
        proc = subprocess.Popen(
            [str(mpiexec), "-n", str(int(ranks)), sys.executable, "-c",
             "from dlo_course.grading.mpi import mpi_sandbox_rank; mpi_sandbox_rank()",
             str(root / "request.json")],
            cwd=root, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, start_new_session=True)
        timed_out = False
        try:
            launcher, _ = proc.communicate(timeout=timeout + startup)
        except subprocess.TimeoutExpired:
            timed_out = True
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except OSError:
                pass
            launcher, _ = proc.communicate()
        try:  # a rank left behind by the launcher
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        launcher_text = launcher.decode(errors="replace")[-3000:]
        results = []
        for rank in range(int(ranks)):
            log = root / f"rank{rank}" / "output.txt"
            output = log.read_bytes()[-20_000:].decode(errors="replace") if log.is_file() else ""
            result: dict[str, Any] = {"status": "error", "value": None, "output": output,
                                      "message": ""}
            path = root / f"rank{rank}.json"
            text = path.read_text() if path.is_file() else ""
            if text:
                read_result(text, result)
            elif timed_out:
                result.update(status="timeout", message=f"the exercise ran longer than its "
                                                        f"time limit ({timeout:g} s)")
            else:
                result["message"] = (f"rank {rank} ended without a result (mpiexec exit code "
                                     f"{proc.returncode})\n{launcher_text}")
            results.append(result)
        shutil.rmtree(root, ignore_errors=True)
    return results
