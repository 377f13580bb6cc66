"""Grading: lesson 11, reproducibility (reference: torch.optim.Adam,
dlo_course.evaluation.seed_interval)."""

import numpy as np
import pytest
import torch

from dlo_course.evaluation import seed_interval

pytestmark = pytest.mark.notebook("11_reproducibility")

ADAM_SETTINGS = [(1e-3, (0.9, 0.999), 1e-8), (0.1, (0.5, 0.9), 1e-3)]


def adam_inputs():
    rng = np.random.default_rng(11)
    for lr, betas, eps in ADAM_SETTINGS:
        start = rng.normal(size=(3, 4))
        grads = [rng.normal(size=start.shape) * 10**rng.uniform(-3, 2) for _ in range(7)]
        yield lr, betas, eps, start, grads


def probe_adam_step(fn, cases):
    """Seven steps per setting, each from the student's own previous state."""
    out = []
    for lr, betas, eps, start, grads in cases:
        p, m, v = np.array(start), np.zeros_like(start), np.zeros_like(start)
        steps = []
        for t, g in enumerate(grads, start=1):
            g = np.array(g)
            inputs = (p.copy(), g.copy(), m.copy(), v.copy())
            p_new, m, v = (np.asarray(x, dtype=np.float64) for x in
                           fn(p, g, m, v, t, lr=lr, beta1=betas[0], beta2=betas[1], eps=eps))
            kept = all(np.array_equal(a, b) for a, b in zip(inputs, (p, g)))
            p = p_new
            steps.append({"p": p, "m": m, "v": v, "inputs_kept": kept})
        out.append(steps)
    return out


@pytest.mark.exercise("adam_step", points=3, reference="torch.optim.Adam.step")
def test_adam_step(student):
    cases = list(adam_inputs())
    got = student.run(probe_adam_step, cases)
    for (lr, betas, eps, start, grads), steps in zip(cases, got, strict=True):
        theta = torch.tensor(start, dtype=torch.float64, requires_grad=True)
        opt = torch.optim.Adam([theta], lr=lr, betas=betas, eps=eps)
        assert len(steps) == len(grads)
        for g, step in zip(grads, steps):
            theta.grad = torch.tensor(g)
            opt.step()
            assert step["inputs_kept"], "inputs must not be modified"
            np.testing.assert_allclose(step["p"], theta.detach().numpy(), rtol=1e-9, atol=1e-12)
            state = opt.state[theta]
            np.testing.assert_allclose(step["m"], state["exp_avg"].numpy(), rtol=1e-9,
                                       atol=1e-15)
            np.testing.assert_allclose(step["v"], state["exp_avg_sq"].numpy(), rtol=1e-9,
                                       atol=1e-15)


# --------------------------------------------------------------- seeds: intervals and bands


def seed_samples(rng):
    """Final returns of 2 to 11 seeds, and learning curves of (2 to 11 seeds, 1 to 40 points)."""
    values = [rng.normal(rng.uniform(-300, 0), rng.uniform(0.1, 80), size=rng.integers(2, 12))
              for _ in range(12)]
    curves = [rng.normal(0, 50, size=(rng.integers(2, 12), rng.integers(1, 40))).cumsum(axis=1)
              for _ in range(8)]
    return values + curves + [np.array([1.0, 2.0, 3.0]), np.array([[1.0, 10.0], [2.0, 10.0],
                                                                  [3.0, 13.0]])]


SEED_BAD = [np.array([5.0]), np.zeros((1, 4)), np.arange(12.0)]  # 1 seed, 1 seed, 12 seeds


def probe_seed_interval(fn, samples):
    raised = []
    for bad in SEED_BAD:
        try:
            fn(np.array(bad))
            raised.append(None)
        except Exception as err:  # noqa: BLE001
            raised.append(type(err).__name__)
    return {"intervals": [[np.asarray(x, dtype=np.float64) for x in fn(np.array(s))]
                          for s in samples], "raised": raised}


@pytest.mark.exercise("seed_interval", points=3, reference="dlo_course.evaluation.seed_interval")
def test_seed_interval(student):
    samples = seed_samples(np.random.default_rng())  # fresh seeds' results at every grading
    got = student.run(probe_seed_interval, samples)
    for sample, values in zip(samples, got["intervals"], strict=True):
        expected = seed_interval(sample)
        assert len(values) == 3, "return (mean, low, high)"
        for name, value, ref in zip(("mean", "low", "high"), values, expected, strict=True):
            ref = np.asarray(ref)
            assert value.shape == ref.shape, (f"{name}: shape {value.shape} for values of shape "
                                              f"{sample.shape}, expected {ref.shape}")
            np.testing.assert_allclose(value, ref, rtol=1e-9, atol=1e-9,
                                       err_msg=f"{name}, values of shape {sample.shape}")
    for bad, raised in zip(SEED_BAD, got["raised"], strict=True):
        assert raised == "ValueError", (f"values of shape {bad.shape} ({bad.shape[0]} seeds) "
                                        f"must raise ValueError ({raised})")


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_seeds", points=1)
def test_prediction_seeds(written_answer):
    written_answer.check()
