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


# answer -> (grading test file, the probe whose result on the answer the tests compare with)
PROBES = {
    "q_iteration_sweep": ("test_01_rl_and_the_bellman_equation.py", "probe_q_iteration_sweep"),
    "pack_gradients": ("test_08_learning_parallelisation_with_mpi.py", "probe_pack_gradients"),
}
