"""Grading: lesson 8, parallel learning (reference: dlo_course.mpi.allreduce_gradients).

allreduce_gradients needs several MPI ranks; its single-rank behaviour, packing and
reduction are reproduced here exactly as it computes them (one flat float32 buffer, summed,
divided by the number of ranks for the mean).
"""

import numpy as np
import pytest
import torch
from torch import nn

pytestmark = pytest.mark.notebook("08_learning_parallelisation_with_mpi")


def library_pack(module):
    # dlo_course.mpi.allreduce_gradients: trainable parameters in order, None grads as zeros
    params = [p for p in module.parameters() if p.requires_grad]
    return torch.cat([(p.grad if p.grad is not None else torch.zeros_like(p)).reshape(-1)
                      for p in params]).numpy()


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
    expected = library_pack(make_module())
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
