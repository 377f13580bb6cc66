"""PyBullet's build-time banner (written to stderr by its C code at import) comes from rank 0
only under mpiexec: dlo_course.mpi_env, checked in subprocesses that look like MPI ranks."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from dlo_course import mpi_env

CODE = ("from dlo_course.mpi_env import import_pybullet_quietly; import_pybullet_quietly(); "
        "import dlo_course.simulation")


def stderr_of_rank(rank: str | None) -> str:
    hidden = mpi_env.LAUNCHER_VARS + mpi_env.RANK_VARS
    env = {k: v for k, v in os.environ.items() if k not in hidden}
    if rank is not None:
        env.update(PMI_RANK=rank, PMI_SIZE="2")
    result = subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stderr


@pytest.mark.parametrize("rank, banner", [(None, True), ("0", True), ("1", False)])
def test_the_banner_comes_from_rank_0_only(rank, banner):
    assert ("pybullet build time" in stderr_of_rank(rank)) == banner


def test_launcher_rank(monkeypatch):
    for name in mpi_env.LAUNCHER_VARS + mpi_env.RANK_VARS:
        monkeypatch.delenv(name, raising=False)
    assert not mpi_env.launched() and mpi_env.launcher_rank() == 0
    monkeypatch.setenv("OMPI_COMM_WORLD_RANK", "3")
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "4")
    assert mpi_env.launched() and mpi_env.launcher_rank() == 3
