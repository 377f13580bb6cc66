"""The grader's own answers to the exercises the library has no reference for.

Instructor-only: ``dlo-course course release --student`` leaves this file out of the student
bundle (its functions *are* answers) and writes instead ``answers.json``: what each probe of
:data:`PROBES` returns on these answers, recorded as plain data. The grading tests ask
:func:`dlo_course.grading.bundle.answer_result`, which runs the probe on the answer here when this file
exists, and reads the recorded result otherwise; so a student's self-check grades exactly as
the instructor's, without the answers' code.

Never imported by a sandboxed exercise: only the grader's own process loads it.
"""

import numpy as np
import torch

from dlo_course.ddpg import bellman_target


def q_iteration_sweep(q, next_state, reward, done, gamma):
    """(S, A) -> (S, A): eq. (1) with the greedy next action, max_a' Q(s', a')."""
    best_next = torch.as_tensor(q.max(axis=1)[next_state])
    return bellman_target(torch.as_tensor(reward), best_next, torch.as_tensor(done), gamma).numpy()


def pack_gradients(module):
    """(n,) float32: the trainable parameters' gradients in order, a missing one as zeros,
    as dlo_course.mpi.allreduce_gradients packs them."""
    params = [p for p in module.parameters() if p.requires_grad]
    return torch.cat([(p.grad if p.grad is not None else torch.zeros_like(p)).reshape(-1)
                      for p in params]).numpy().astype(np.float32)


# Lesson 11: 95% t-intervals over seeds (two-sided, n - 1 degrees of freedom).
T_975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306,
         9: 2.262, 10: 2.228}


def _interval(values, axis=0):
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[axis]
    mean = values.mean(axis=axis)
    half = T_975[n - 1] * values.std(axis=axis, ddof=1) / np.sqrt(n)
    return mean, mean - half, mean + half


def mean_interval(values):
    """(n,) -> (mean, low, high) floats: the mean and its 95% t-interval."""
    return tuple(float(x) for x in _interval(values))


def mean_curve_with_band(curves):
    """(seeds, points) -> three (points,) arrays: mean curve and its 95% t-band over seeds."""
    return _interval(curves, axis=0)


def recipes_differ(a, b):
    """True when the two recipes' 95% intervals of the final return do not overlap."""
    _, low_a, high_a = _interval(a)
    _, low_b, high_b = _interval(b)
    return bool(high_a < low_b or high_b < low_a)


# answer -> (grading test file, the probe whose result on the answer the tests compare with)
PROBES = {
    "q_iteration_sweep": ("test_01_rl_and_the_bellman_equation.py", "probe_q_iteration_sweep"),
    "pack_gradients": ("test_08_learning_parallelisation_with_mpi.py", "probe_pack_gradients"),
    "mean_interval": ("test_11_reproducibility.py", "probe_mean_interval_fixed"),
    "mean_curve_with_band": ("test_11_reproducibility.py", "probe_mean_curve_with_band_fixed"),
    "recipes_differ": ("test_11_reproducibility.py", "probe_recipes_differ_fixed"),
}
