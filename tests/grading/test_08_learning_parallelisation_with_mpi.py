"""Grading: lesson 8, parallel learning (reference: dlo_course.mpi.allreduce_gradients).

allreduce_gradients needs several MPI ranks: the reduction is checked against the sum (or
mean) computed here, the packing against the grader's own answer (``answers.py``, kept out of
the student bundle, see :func:`dlo_course.grading.bundle.answer_result`), and
``sum_gradients_over_ranks`` in 2 real MPI processes against allreduce_gradients itself.
"""

import os
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from dlo_course.grading.bundle import answer_result

pytestmark = pytest.mark.notebook("08_learning_parallelisation_with_mpi")
DEFAULT_TIMEOUT = float(os.environ.get("DLO_COURSE_GRADING_TIMEOUT", 60))  # as conftest.py
GRADING_DIR = Path(__file__).resolve().parent


def make_module():
    torch.manual_seed(8)
    net = nn.Sequential(nn.Linear(4, 6), nn.ReLU(), nn.Linear(6, 3), nn.Linear(3, 2))
    net[2].bias.requires_grad_(False)  # frozen: not part of the buffer
    unused = nn.Linear(2, 2)  # no gradient at all after backward
    model = nn.ModuleDict({"net": net, "unused": unused})
    net(torch.randn(5, 4)).pow(2).sum().backward()
    return model


SHAPES = [(6, 4), (6,), (1, 6), (1,)]


def reduce_cases():
    rng = np.random.default_rng(8)
    for n_ranks in (1, 2, 3, 32):
        per_rank = [[rng.normal(size=s).astype(np.float32) for s in SHAPES]
                    for _ in range(n_ranks)]
        for op in ("sum", "mean"):
            yield per_rank, op


def probe_reduce_gradients(fn, cases):
    out = []
    for per_rank, op in cases:
        got = fn([[np.array(g) for g in grads] for grads in per_rank], op)
        out.append([np.asarray(g) for g in got])
    return out


def check_reduce_gradients(student):
    cases = list(reduce_cases())
    got = student.run(probe_reduce_gradients, cases)
    for result, (per_rank, op) in zip(got, cases, strict=True):
        flat = np.stack([np.concatenate([g.ravel() for g in grads]) for grads in per_rank])
        expected = flat.sum(axis=0) / (len(per_rank) if op == "mean" else 1)
        assert len(result) == len(SHAPES)
        for g, shape in zip(result, SHAPES):
            assert np.shape(g) == shape
        np.testing.assert_allclose(np.concatenate([np.ravel(g) for g in result]), expected,
                                   rtol=1e-5, atol=1e-6, err_msg=f"op={op!r}, "
                                                                 f"{len(per_rank)} ranks")


def probe_reduce_gradients_bad_op(fn):
    try:
        fn([[np.ones(2)]], "median")
    except Exception as err:  # noqa: BLE001
        return type(err).__name__
    return None


@pytest.mark.exercise("reduce_gradients", points=1.5,
                      reference="dlo_course.mpi.allreduce_gradients")
def test_reduce_gradients(student):
    check_reduce_gradients(student)


@pytest.mark.exercise("reduce_gradients", points=0.5,
                      reference="dlo_course.mpi.allreduce_gradients")
def test_reduce_gradients_refuses_unknown_op(student):
    """The secondary requirement (the ValueError), worth points only with a right result."""
    try:
        check_reduce_gradients(student)
    except AssertionError:
        pytest.fail("the reduction itself is wrong: no points for refusing an unknown op",
                    pytrace=False)
    raised = student.run(probe_reduce_gradients_bad_op)
    assert raised == "ValueError", f"op='median' must raise ValueError (raised: {raised})"


def probe_pack_gradients(fn):
    return np.asarray(fn(make_module()))


@pytest.mark.exercise("pack_gradients", points=1, reference="dlo_course.mpi.allreduce_gradients")
def test_pack_gradients(student):
    got = student.run(probe_pack_gradients)
    expected = answer_result(GRADING_DIR, "pack_gradients", probe_pack_gradients)
    assert got.ndim == 1 and got.shape == expected.shape, \
        f"shape {got.shape}, expected {expected.shape}"
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, expected)


def unpack_input():
    model = make_module()
    n = sum(p.numel() for p in model.parameters() if p.requires_grad)
    return model, np.arange(n, dtype=np.float32) / 7


def probe_unpack_gradients(fn):
    model, flat = unpack_input()
    frozen_before = [p.grad for p in model.parameters() if not p.requires_grad]
    fn(model, flat.copy())
    return {"grads": [None if p.grad is None else p.grad.detach().clone()
                      for p in model.parameters() if p.requires_grad],
            "frozen_kept": [p.grad for p in model.parameters()
                            if not p.requires_grad] == frozen_before}


@pytest.mark.exercise("unpack_gradients", points=1,
                      reference="dlo_course.mpi.allreduce_gradients")
def test_unpack_gradients(student):
    got = student.run(probe_unpack_gradients)
    model, flat = unpack_input()
    params = [p for p in model.parameters() if p.requires_grad]
    assert len(got["grads"]) == len(params)
    offset = 0
    for grad, p in zip(got["grads"], params):
        assert grad is not None, "every trainable parameter must receive its gradient"
        np.testing.assert_allclose(grad.numpy(), flat[offset:offset + p.numel()].reshape(p.shape))
        offset += p.numel()
    assert got["frozen_kept"], "frozen parameters must keep their gradient"


# ------------------------------------------------- sum_gradients_over_ranks (real MPI)

MPI_RANKS = 2
MPI_UPDATES = 3


def probe_sum_gradients_over_ranks(fn, library=False):
    """Runs in each of MPI_RANKS sandboxed MPI processes: a small DDPG agent per rank, with
    different initial weights and data on each, broadcast from rank 0, then MPI_UPDATES
    updates whose gradients are combined by fn(module, comm) (``library``: by the library's
    allreduce_gradients(module, "sum") instead). Returns this rank's gradients as applied,
    in order, and its final networks."""
    from dlo_course import mpi
    from dlo_course.ddpg import DDPG, DDPGConfig

    comm = mpi.comm()
    rank = comm.Get_rank()
    torch.manual_seed(80 + rank)  # different weights on each rank, until the broadcast
    agent = DDPG(5, 2, -1.0, 1.0, DDPGConfig(hidden_sizes=(16, 16), tau=0.1))
    mpi.broadcast_module(agent.actor)
    mpi.broadcast_module(agent.critic)
    agent.sync_targets()
    applied = []

    def reducer(module):
        if library:
            mpi.allreduce_gradients(module, op="sum")
        else:
            fn(module, comm)
        applied.append([None if p.grad is None else p.grad.detach().clone()
                        for p in module.parameters() if p.requires_grad])

    rng = np.random.default_rng(rank)  # different data on each rank
    for _ in range(MPI_UPDATES):
        agent.update({"obs": rng.normal(size=(8, 5)), "act": rng.uniform(-1, 1, (8, 2)),
                      "rew": rng.normal(size=8), "next_obs": rng.normal(size=(8, 5)),
                      "done": (rng.random(8) < 0.25).astype(float)}, reducer)
    nets = {name: [t.clone() for t in getattr(agent, name).state_dict().values()]
            for name in ("actor", "critic", "actor_target", "critic_target")}
    return {"rank": rank, "size": comm.Get_size(), "applied": applied, "nets": nets}


@pytest.mark.timeout(2 * (2 * DEFAULT_TIMEOUT + 120))  # two MPI runs, each may start slowly
@pytest.mark.exercise("sum_gradients_over_ranks", points=3,
                      reference="dlo_course.mpi.allreduce_gradients")
def test_sum_gradients_over_ranks(student, mpi_reference):
    got = student.run_mpi(probe_sum_gradients_over_ranks, ranks=MPI_RANKS)
    want = mpi_reference(probe_sum_gradients_over_ranks, True, ranks=MPI_RANKS)
    assert [r["rank"] for r in got] == list(range(MPI_RANKS))
    assert all(r["size"] == MPI_RANKS for r in got)
    first = got[0]["nets"]
    for rank, mine in enumerate(got[1:], start=1):
        for name, tensors in mine["nets"].items():
            assert all(torch.equal(a, b) for a, b in zip(tensors, first[name], strict=True)), \
                f"after {MPI_UPDATES} updates, rank {rank}'s {name} differs from rank 0's: " \
                f"every rank must apply the same combined gradient"
    for rank, (mine, ref) in enumerate(zip(got, want, strict=True)):
        assert len(mine["applied"]) == len(ref["applied"]), \
            f"rank {rank}: {len(mine['applied'])} reductions, expected {len(ref['applied'])}"
        for call, (grads, ref_grads) in enumerate(zip(mine["applied"], ref["applied"])):
            assert len(grads) == len(ref_grads)
            for g, r in zip(grads, ref_grads):
                assert g is not None, f"rank {rank}, reduction {call}: a gradient is missing"
                torch.testing.assert_close(
                    g, r, rtol=1e-5, atol=1e-7, msg=lambda m: (
                        f"rank {rank}, reduction {call}: the gradient applied is not the sum of "
                        f"the ranks' gradients: {m}"))
        for name, tensors in mine["nets"].items():
            for a, b in zip(tensors, ref["nets"][name], strict=True):
                torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7, msg=lambda m: (
                    f"rank {rank}: {name} after {MPI_UPDATES} updates differs from the "
                    f"library's result: {m}"))


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_transitions", points=1)
def test_prediction_transitions(written_answer):
    written_answer.check()
