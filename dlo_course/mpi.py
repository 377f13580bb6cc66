"""Parallel learning with MPI (Section IV-F of the paper).

The paper trains 32 agents at once, one per CPU core, each an MPI process ("rank") with its
own environment, goal, replay buffer and exploration noise. They share one set of networks:

* at the start, rank 0's freshly initialised networks are copied to every rank
  (:func:`broadcast_module`);
* at every update, each rank computes gradients on its own batch, the gradients of all ranks
  are summed (:func:`allreduce_gradients`) and every rank applies that same summed gradient.
  Same starting weights + same gradients + same Adam state = the same new weights, so the 32
  copies of the networks stay identical without ever being copied again.

Run a script under MPI with ``mpiexec -n 4 python script.py`` (or ``mpiexec -n 4 dlo-course
train ...``). Started without ``mpiexec``, every helper here behaves as for a single process,
and mpi4py is not even imported: a notebook never starts MPI by accident.
"""

from __future__ import annotations

import hashlib
import sys
from typing import Any, Sequence

import numpy as np
import torch
from torch import nn

from dlo_course.mpi_env import launched

_comm: Any = None
_comm_checked = False


def comm() -> Any:
    """The world communicator (``mpi4py.MPI.COMM_WORLD``), or ``None`` for a single process."""
    global _comm, _comm_checked
    if not _comm_checked:
        if launched() or "mpi4py.MPI" in sys.modules:
            try:
                from mpi4py import MPI
            except ImportError as err:
                raise RuntimeError("this process was started by mpiexec but mpi4py is not "
                                   "installed: pip install mpi4py") from err
            _comm = MPI.COMM_WORLD
        _comm_checked = True
    return _comm


def rank() -> int:
    """This process's index among the agents, 0 ... size() - 1 (0 without MPI)."""
    c = comm()
    return 0 if c is None else c.Get_rank()


def size() -> int:
    """How many agents (MPI processes) take part (1 without MPI)."""
    c = comm()
    return 1 if c is None else c.Get_size()


def is_root() -> bool:
    """True on rank 0, the rank that writes logs and files."""
    return rank() == 0


def barrier() -> None:
    """Wait until every rank gets here."""
    if size() > 1:
        comm().Barrier()


def rank_seed(seed: int, rank: int) -> int:
    """The seed of agent ``rank`` in a run seeded with ``seed``.

    Every agent needs its own seed, otherwise all 32 would draw the same goals and the same
    noise and the parallelism would gain nothing. The authors' code seeds rank r with
    9527 + r, so two runs differ only by a shift of ranks. Here the seed is derived from the
    pair (run seed, rank) by NumPy's ``SeedSequence``, which hashes it: every (seed, rank)
    pair gets an unrelated stream, and changing the run seed changes every agent.

    Returns:
        An integer in [0, 2**32).
    """
    return int(np.random.SeedSequence([int(seed), int(rank)]).generate_state(1)[0])


def broadcast_module(module: nn.Module, root: int = 0) -> None:
    """Overwrite, in place, the parameters and buffers of ``module`` on every rank with
    those of rank ``root``. Called once at the start so all agents begin identical."""
    if size() == 1:
        return
    with torch.no_grad():
        for tensor in module.state_dict().values():
            # .numpy() shares memory with the tensor: receiving into it updates the module.
            comm().Bcast(tensor.numpy(), root=root)


def allreduce_gradients(module: nn.Module, op: str = "sum") -> None:
    """Replace, in place, each parameter's ``.grad`` by its sum (or mean) over all ranks.

    Call between ``loss.backward()`` and ``optimizer.step()``. The gradients are packed in one
    flat float32 buffer so all of them travel in a single MPI message.

    Args:
        module: the network whose gradients to combine (the actor or the critic).
        op: ``"sum"``, as in the paper (one gradient equal to the sum of the 32 agents'), or
            ``"mean"``. With Adam the choice barely matters: Adam divides each step by a
            running estimate of the gradient's magnitude, so scaling every gradient by 32
            hardly changes the step. With plain SGD, summing would multiply the learning
            rate by the number of agents.
    """
    if op not in ("sum", "mean"):
        raise ValueError(f"op must be 'sum' or 'mean', got {op!r}")
    n = size()
    if n == 1:
        return
    from mpi4py import MPI

    params = [p for p in module.parameters() if p.requires_grad]
    for p in params:
        if p.grad is None:  # a parameter unused by this loss: contribute zeros
            p.grad = torch.zeros_like(p)
    flat = torch.cat([p.grad.reshape(-1) for p in params]).numpy()
    comm().Allreduce(MPI.IN_PLACE, flat, op=MPI.SUM)
    if op == "mean":
        flat /= n
    offset = 0
    for p in params:
        k = p.numel()
        p.grad.copy_(torch.from_numpy(flat[offset:offset + k]).view_as(p))
        offset += k


def allreduce_scalars(values: float | Sequence[float], op: str = "mean") -> np.ndarray:
    """Combine a few numbers element-wise over all ranks.

    Args:
        values: a number or a sequence of numbers, the same length on every rank.
        op: ``"mean"``, ``"sum"``, ``"min"`` or ``"max"``.

    Returns:
        float64 array of the same length as ``values`` (length 1 for a number), identical on
        every rank.
    """
    x = np.atleast_1d(np.asarray(values, dtype=np.float64)).copy()
    if op not in ("mean", "sum", "min", "max"):
        raise ValueError(f"op must be mean, sum, min or max, got {op!r}")
    if size() == 1:
        return x
    from mpi4py import MPI

    mpi_op = {"mean": MPI.SUM, "sum": MPI.SUM, "min": MPI.MIN, "max": MPI.MAX}[op]
    comm().Allreduce(MPI.IN_PLACE, x, op=mpi_op)
    return x / size() if op == "mean" else x


def allgather(obj: Any) -> list[Any]:
    """Every rank's ``obj`` (any picklable object), as a list indexed by rank, on every rank."""
    return [obj] if size() == 1 else comm().allgather(obj)


def gather(obj: Any, root: int = 0) -> list[Any] | None:
    """Every rank's ``obj`` as a list indexed by rank on rank ``root``; ``None`` elsewhere."""
    return [obj] if size() == 1 else comm().gather(obj, root=root)


def stats_over_ranks(value: float) -> dict[str, float]:
    """Mean, min and max of one number over all ranks (for logging), on every rank."""
    values = np.asarray(allgather(float(value)), dtype=np.float64)
    return {"mean": float(values.mean()), "min": float(values.min()),
            "max": float(values.max())}


def module_digest(module: nn.Module) -> str:
    """A short hash of a module's parameters and buffers (exact bytes)."""
    h = hashlib.sha256()
    for name, tensor in module.state_dict().items():
        h.update(name.encode())
        h.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def modules_in_sync(*modules: nn.Module) -> bool:
    """True if every rank holds bit-identical copies of ``modules``.

    MPI's sum over ranks is computed by every rank; the MPI standard only *advises* that
    all ranks get the same bits. This check (cheap: one hash per rank) verifies it.
    """
    digests = allgather(tuple(module_digest(m) for m in modules))
    return all(d == digests[0] for d in digests)
