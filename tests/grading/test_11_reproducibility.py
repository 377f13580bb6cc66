"""Grading: lesson 11, reproducibility (reference: SimParams.steps_per_action, torch.optim.Adam)."""

from pathlib import Path

import numpy as np
import pytest
import torch

from dlo_course.grading.bundle import answer_result
from dlo_course.simulation import SimParams

pytestmark = pytest.mark.notebook("11_reproducibility")
GRADING_DIR = Path(__file__).resolve().parent

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
# The grader's own answers live in answers.py, which the student bundle leaves out. Inputs from
# a fixed seed are checked against the answers' results (recorded in the bundle's
# answers.json); where answers.py is present (the instructor's grading), fresh inputs too.
ANSWERS = GRADING_DIR / "answers.py"


def fresh_answer(name, probe):
    """``probe`` on the grader's own ``name`` (answers.py), or None in a student bundle."""
    if not ANSWERS.is_file():
        return None
    return answer_result(GRADING_DIR, name, probe)


def seed_samples(seed):
    rng = np.random.default_rng(seed)  # seed None: fresh entropy
    return [rng.normal(rng.uniform(-300, 0), rng.uniform(0.1, 80), size=rng.integers(2, 11))
            for _ in range(12)]


def seed_curves(seed):
    rng = np.random.default_rng(seed)
    return [rng.normal(0, 50, size=(rng.integers(2, 11), rng.integers(1, 40))).cumsum(axis=1)
            for _ in range(8)]


def seed_pairs(seed):
    rng = np.random.default_rng(seed)
    pairs = []
    for gap in (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 20.0) * 3:
        a = rng.normal(0.0, 1.0, size=rng.integers(2, 11))
        b = rng.normal(gap, rng.uniform(0.2, 2.0), size=rng.integers(2, 11))
        pairs.append((a, b) if rng.random() < 0.5 else (b, a))
    a = np.array([1.0, 2.0, 3.0])
    return pairs + [(a, a + 100.0), (a, a + 0.1)]


def probe_mean_interval(fn, samples):
    return [[float(x) for x in fn(np.array(s))] for s in samples]


def probe_mean_interval_fixed(fn):
    return probe_mean_interval(fn, seed_samples(1101))


def check_intervals(got, want, samples):
    for s, values, expected in zip(samples, got, want, strict=True):
        np.testing.assert_allclose(values, expected, rtol=1e-9, atol=1e-9, err_msg=f"n = {len(s)}")


@pytest.mark.exercise("mean_interval", points=1)
def test_mean_interval(student):
    fixed = seed_samples(1101)
    check_intervals(student.run(probe_mean_interval, fixed),
                    answer_result(GRADING_DIR, "mean_interval", probe_mean_interval_fixed), fixed)
    fresh = seed_samples(None)
    want = fresh_answer("mean_interval", lambda fn: probe_mean_interval(fn, fresh))
    if want is not None:
        check_intervals(student.run(probe_mean_interval, fresh), want, fresh)


def probe_mean_curve_with_band(fn, curves):
    return [[np.asarray(x, dtype=np.float64) for x in fn(np.array(c))] for c in curves]


def probe_mean_curve_with_band_fixed(fn):
    return probe_mean_curve_with_band(fn, seed_curves(1102))


def check_bands(got, want, curves):
    for c, bands, expected in zip(curves, got, want, strict=True):
        for name, value, ref in zip(("mean", "low", "high"), bands, expected, strict=True):
            value, ref = np.asarray(value), np.asarray(ref)
            assert value.shape == ref.shape, f"{name}: shape {value.shape}, not {ref.shape}"
            np.testing.assert_allclose(value, ref, rtol=1e-9, atol=1e-9,
                                       err_msg=f"{name}, curves of shape {c.shape}")


@pytest.mark.exercise("mean_curve_with_band", points=2)
def test_mean_curve_with_band(student):
    fixed = seed_curves(1102)
    check_bands(student.run(probe_mean_curve_with_band, fixed),
                answer_result(GRADING_DIR, "mean_curve_with_band", probe_mean_curve_with_band_fixed),
                fixed)
    fresh = seed_curves(None)
    want = fresh_answer("mean_curve_with_band", lambda fn: probe_mean_curve_with_band(fn, fresh))
    if want is not None:
        check_bands(student.run(probe_mean_curve_with_band, fresh), want, fresh)


def probe_recipes_differ(fn, pairs):
    return [bool(fn(np.array(a), np.array(b))) for a, b in pairs]


def probe_recipes_differ_fixed(fn):
    return probe_recipes_differ(fn, seed_pairs(1103))


@pytest.mark.exercise("recipes_differ", points=1)
def test_recipes_differ(student):
    want = answer_result(GRADING_DIR, "recipes_differ", probe_recipes_differ_fixed)
    assert any(want) and not all(want)
    assert student.run(probe_recipes_differ, seed_pairs(1103)) == list(want)
    fresh = seed_pairs(None)
    want = fresh_answer("recipes_differ", lambda fn: probe_recipes_differ(fn, fresh))
    if want is not None:
        assert student.run(probe_recipes_differ, fresh) == want


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_seeds", points=1)
def test_prediction_seeds(written_answer):
    written_answer.check()
