"""Grading: lesson 11, reproducibility (reference: SimParams.steps_per_action, torch.optim.Adam)."""

import numpy as np
import pytest
import torch

from dlo_course.simulation import SimParams

pytestmark = pytest.mark.notebook("11_reproducibility")

STEP_CASES = [(mode, duration, step) for mode in ("code", "paper")
              for duration, step in [(0.06, 0.003), (0.06, 0.004), (0.001, 0.003), (0.1, 0.03)]]


def probe_steps_per_action(fn):
    try:
        fn("fast", 0.06, 0.003)
        raised = None
    except Exception as err:  # noqa: BLE001
        raised = type(err).__name__
    return [int(fn(*case)) for case in STEP_CASES], raised


@pytest.mark.exercise("steps_per_action", points=1,
                      reference="dlo_course.simulation.SimParams.steps_per_action")
def test_steps_per_action(student):
    got, raised = student.run(probe_steps_per_action)
    for (mode, duration, step), value in zip(STEP_CASES, got, strict=True):
        expected = SimParams(time_mode=mode, action_duration=duration,
                             time_step=step).steps_per_action
        assert value == expected, (mode, duration, step)
    assert raised == "ValueError", f"an unknown mode must raise ValueError ({raised})"


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


# --------------------------------------------------------------- seeds: bands and intervals
# The reference is written here (not a recorded output). Each test draws its inputs twice:
# from a fixed seed (the same checks at every grading) and afresh (new inputs every time).
T_975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306,
         9: 2.262, 10: 2.228}


def reference_interval(values, axis=0):
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[axis]
    mean = values.mean(axis=axis)
    half = T_975[n - 1] * values.std(axis=axis, ddof=1) / np.sqrt(n)
    return mean, mean - half, mean + half


def seed_samples(seed):
    rng = np.random.default_rng(seed)  # seed None: fresh entropy
    return [rng.normal(rng.uniform(-300, 0), rng.uniform(0.1, 80), size=rng.integers(2, 11))
            for _ in range(12)]


def probe_mean_interval(fn, samples):
    return [[float(x) for x in fn(np.array(s))] for s in samples]


@pytest.mark.exercise("mean_interval", points=1)
def test_mean_interval(student):
    samples = seed_samples(1101) + seed_samples(None)
    got = student.run(probe_mean_interval, samples)
    for s, values in zip(samples, got, strict=True):
        np.testing.assert_allclose(values, [float(x) for x in reference_interval(s)],
                                   rtol=1e-9, atol=1e-9, err_msg=f"n = {len(s)}")


def probe_mean_curve_with_band(fn, curves):
    return [[np.asarray(x, dtype=np.float64) for x in fn(np.array(c))] for c in curves]


@pytest.mark.exercise("mean_curve_with_band", points=2)
def test_mean_curve_with_band(student):
    curves = []
    for rng in (np.random.default_rng(1102), np.random.default_rng()):
        curves += [rng.normal(0, 50, size=(rng.integers(2, 11), rng.integers(1, 40))).cumsum(axis=1)
                   for _ in range(8)]
    got = student.run(probe_mean_curve_with_band, curves)
    for c, (mean, low, high) in zip(curves, got, strict=True):
        ref = reference_interval(c, axis=0)
        for name, value, expected in zip(("mean", "low", "high"), (mean, low, high), ref):
            assert value.shape == expected.shape, f"{name}: shape {value.shape}, not {expected.shape}"
            np.testing.assert_allclose(value, expected, rtol=1e-9, atol=1e-9,
                                       err_msg=f"{name}, curves of shape {c.shape}")


def probe_recipes_differ(fn, pairs):
    return [bool(fn(np.array(a), np.array(b))) for a, b in pairs]


@pytest.mark.exercise("recipes_differ", points=1)
def test_recipes_differ(student):
    pairs = []
    for rng in (np.random.default_rng(1103), np.random.default_rng()):
        for gap in (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 20.0) * 3:
            a = rng.normal(0.0, 1.0, size=rng.integers(2, 11))
            b = rng.normal(gap, rng.uniform(0.2, 2.0), size=rng.integers(2, 11))
            pairs.append((a, b) if rng.random() < 0.5 else (b, a))
    a = np.array([1.0, 2.0, 3.0])
    pairs.append((a, a + 100.0))
    pairs.append((a, a + 0.1))
    got = student.run(probe_recipes_differ, pairs)
    expected = []
    for a, b in pairs:
        _, low_a, high_a = reference_interval(a)
        _, low_b, high_b = reference_interval(b)
        expected.append(bool(high_a < low_b or high_b < low_a))
    assert any(expected) and not all(expected)
    assert got == expected
