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
