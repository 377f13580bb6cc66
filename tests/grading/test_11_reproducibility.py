"""Grading: lesson 11, reproducibility (reference: SimParams.steps_per_action, torch.optim.Adam)."""

import numpy as np
import pytest
import torch

from dlo_course.simulation import SimParams

pytestmark = pytest.mark.notebook("11_reproducibility")


@pytest.mark.exercise("steps_per_action", points=1)
def test_steps_per_action(exercise):
    for mode in ("code", "paper"):
        for duration, step in [(0.06, 0.003), (0.06, 0.004), (0.001, 0.003), (0.1, 0.03)]:
            expected = SimParams(time_mode=mode, action_duration=duration,
                                 time_step=step).steps_per_action
            assert int(exercise(mode, duration, step)) == expected, (mode, duration, step)
    with pytest.raises(ValueError):
        exercise("fast", 0.06, 0.003)


@pytest.mark.exercise("adam_step", points=3)
def test_adam_step(exercise):
    rng = np.random.default_rng(11)
    for lr, betas, eps in [(1e-3, (0.9, 0.999), 1e-8), (0.1, (0.5, 0.9), 1e-3)]:
        start = rng.normal(size=(3, 4))
        theta = torch.tensor(start, dtype=torch.float64, requires_grad=True)
        opt = torch.optim.Adam([theta], lr=lr, betas=betas, eps=eps)
        p, m, v = start.copy(), np.zeros_like(start), np.zeros_like(start)
        for t in range(1, 8):
            g = rng.normal(size=start.shape) * 10**rng.uniform(-3, 2)
            theta.grad = torch.tensor(g)
            opt.step()
            inputs = (p.copy(), g.copy(), m.copy(), v.copy())
            p_new, m, v = (np.asarray(x, dtype=np.float64) for x in
                           exercise(p, g, m, v, t, lr=lr, beta1=betas[0], beta2=betas[1], eps=eps))
            for before, after in zip(inputs, (p, g)):
                np.testing.assert_array_equal(before, after, err_msg="inputs must not be modified")
            p = p_new
            np.testing.assert_allclose(p, theta.detach().numpy(), rtol=1e-9, atol=1e-12)
            state = opt.state[theta]
            np.testing.assert_allclose(m, state["exp_avg"].numpy(), rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(v, state["exp_avg_sq"].numpy(), rtol=1e-9, atol=1e-15)
