"""What an MPI launcher told this process, read from its environment variables: without
starting MPI, and without importing mpi4py, torch or PyBullet (the command line asks before
anything heavy is loaded).

:func:`import_pybullet_quietly` is why: PyBullet's C code writes its build-time banner
("pybullet build time: ...") to stderr when it is imported, so ``mpiexec -n 32`` would print it
32 times. Rank 0 keeps it; the other ranks import PyBullet first with stderr silenced, and the
library's later ``import pybullet`` (:mod:`dlo_course.simulation`) finds it loaded and prints
nothing.
"""

from __future__ import annotations

import os
import sys

LAUNCHER_VARS = ("PMI_RANK", "PMI_SIZE", "PMIX_RANK", "OMPI_COMM_WORLD_SIZE", "MPI_LOCALNRANKS")
"""Environment variables that MPI launchers set in the processes they start (MPICH/Hydra and
Slurm's PMI, PMIx, Open MPI). Their absence means "not started by mpiexec"."""

RANK_VARS = ("PMI_RANK", "PMIX_RANK", "OMPI_COMM_WORLD_RANK")
"""The ones among them (and Open MPI's) that hold this process's rank."""


def launched() -> bool:
    """True in a process started by an MPI launcher."""
    return any(name in os.environ for name in LAUNCHER_VARS)


def launcher_rank() -> int:
    """This process's rank as its launcher set it (0 outside MPI, or if none says)."""
    for name in RANK_VARS:
        value = os.environ.get(name, "")
        if value.strip().isdigit():
            return int(value)
    return 0


def import_pybullet_quietly() -> None:
    """On an MPI rank other than 0, import PyBullet with file descriptor 2 (stderr) sent to
    /dev/null, so that its build-time banner is printed once per job, by rank 0. Does nothing
    on rank 0, outside MPI, or once PyBullet is imported."""
    if "pybullet" in sys.modules or launcher_rank() == 0:
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401  (loaded for the library, which imports it later)
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
