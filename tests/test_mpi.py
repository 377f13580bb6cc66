import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from dlo_course import mpi

SCRIPTS = Path(__file__).parent / "mpi_scripts"
MPIEXEC = Path(sys.executable).parent / "mpiexec"


def run_mpi(n: int, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """``mpiexec -n n args...``, asserted to succeed; returns the finished process (its
    captured stdout and stderr)."""
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec next to {sys.executable}")
    # A clean environment for the launcher: no MPI variables inherited from this process.
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI", "MPI", "OMPI"))}
    proc = subprocess.run([str(MPIEXEC), "-n", str(n), *args], capture_output=True, text=True,
                          timeout=timeout, env=env)
    assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    return proc


def test_single_process_helpers():
    assert (mpi.rank(), mpi.size(), mpi.is_root()) == (0, 1, True)
    net = torch.nn.Linear(2, 1)
    net(torch.ones(1, 2)).sum().backward()
    grad = net.weight.grad.clone()
    mpi.broadcast_module(net)
    mpi.allreduce_gradients(net, op="mean")
    assert torch.equal(net.weight.grad, grad)  # one agent: nothing to combine
    assert mpi.allreduce_scalars([1.0, 2.0], "max").tolist() == [1.0, 2.0]
    assert mpi.stats_over_ranks(3.0) == {"mean": 3.0, "min": 3.0, "max": 3.0}
    assert mpi.allgather("x") == ["x"] and mpi.gather("x") == ["x"]
    assert mpi.modules_in_sync(net)
    with pytest.raises(ValueError):
        mpi.allreduce_gradients(net, op="median")


def test_rank_seeds_are_distinct_and_deterministic():
    seeds = [mpi.rank_seed(0, r) for r in range(32)]
    assert len(set(seeds)) == 32
    assert seeds == [mpi.rank_seed(0, r) for r in range(32)]
    assert mpi.rank_seed(1, 0) not in seeds
    assert all(0 <= s < 2**32 for s in seeds)


@pytest.mark.mpi
@pytest.mark.parametrize("op", ["sum", "mean"])
def test_two_ranks_apply_the_reduced_gradient_and_stay_identical(tmp_path, op):
    result_path = tmp_path / "result.json"
    run_mpi(2, sys.executable, str(SCRIPTS / "gradient_sync.py"), op, str(result_path))
    result = json.loads(result_path.read_text())
    assert result == {
        "size": 2,
        "differ_at_start": True,        # the ranks really started different...
        "same_after_broadcast": True,   # ...until rank 0's weights were broadcast
        "local_grads_differ": True,     # each rank learns from its own data...
        "applied_is_reduction": True,   # ...the applied gradient is their sum (or mean)...
        "same_after_updates": True,     # ...so the networks stay bit-identical
        "reduced_calls": 10,            # critic and actor, 5 updates
    }


@pytest.mark.mpi
def test_two_rank_training_from_the_command_line(tmp_path):
    out = tmp_path / "run"
    run_mpi(2, sys.executable, "-m", "dlo_course.cli", "train", "--preset", "smoke",
            "--env", "Pendulum-v1", "--steps-per-episode", "15", "--out", str(out),
            "--no-progress")
    with (out / "progress.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [int(r["transitions"]) for r in rows] == [30, 60]  # 2 agents x 15 steps
    assert all(float(r["reward_min"]) < float(r["reward_max"]) for r in rows)  # own goals
    assert int(rows[-1]["updates"]) > 0
    assert json.loads((out / "config.json").read_text())["n_agents"] == 2
    for name in ("actor.pt", "critic.pt", "checkpoints/episode000002/state_rank1.pt"):
        assert (out / name).exists()
