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


@pytest.mark.exercise("reduce_gradients", points=2)
def test_reduce_gradients(exercise):
    rng = np.random.default_rng(8)
    shapes = [(6, 4), (6,), (1, 6), (1,)]
    for n_ranks in (1, 2, 3, 32):
        per_rank = [[rng.normal(size=s).astype(np.float32) for s in shapes] for _ in range(n_ranks)]
        flat = np.stack([np.concatenate([g.ravel() for g in grads]) for grads in per_rank])
        for op in ("sum", "mean"):
            expected = flat.sum(axis=0) / (n_ranks if op == "mean" else 1)
            got = exercise([[g.copy() for g in grads] for grads in per_rank], op)
            assert len(got) == len(shapes)
            for g, s in zip(got, shapes):
                assert np.shape(g) == s
            np.testing.assert_allclose(np.concatenate([np.ravel(g) for g in got]), expected,
                                       rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError):
        exercise([[np.ones(2)]], "median")


@pytest.mark.exercise("pack_gradients", points=1)
def test_pack_gradients(exercise):
    model = make_module()
    got = np.asarray(exercise(model))
    expected = library_pack(model)
    assert got.ndim == 1 and got.shape == expected.shape, \
        f"shape {got.shape}, expected {expected.shape}"
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, expected)


@pytest.mark.exercise("unpack_gradients", points=1)
def test_unpack_gradients(exercise):
    model = make_module()
    params = [p for p in model.parameters() if p.requires_grad]
    n = sum(p.numel() for p in params)
    flat = np.arange(n, dtype=np.float32) / 7
    frozen_before = [p.grad for p in model.parameters() if not p.requires_grad]
    exercise(model, flat.copy())
    offset = 0
    for p in params:
        assert p.grad is not None, "every trainable parameter must receive its gradient"
        np.testing.assert_allclose(p.grad.numpy(), flat[offset:offset + p.numel()].reshape(p.shape))
        offset += p.numel()
    assert [p.grad for p in model.parameters() if not p.requires_grad] == frozen_before
