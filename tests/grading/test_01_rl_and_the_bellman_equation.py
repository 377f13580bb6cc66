"""Grading: lesson 1, RL and the Bellman equation (reference: dlo_course.ddpg.bellman_target).

Each ``probe_*`` runs in the sandbox on the student's function (and here on the reference)
and returns plain results; the tests compare them in the grader's own process. The library
has no discounted return nor Q-iteration: those references are the grader's own answers
(``answers.py``, kept out of the student bundle, see :func:`dlo_course.grading.bundle.answer_result`).
"""

from pathlib import Path

import numpy as np
import pytest
import torch

from dlo_course.grading.bundle import answer_result
from dlo_course.ddpg import bellman_target

pytestmark = pytest.mark.notebook("01_rl_and_the_bellman_equation")
GRADING_DIR = Path(__file__).resolve().parent


def probe_discounted_return(fn):
    rng = np.random.default_rng(1)
    cases = [(list(rng.normal(size=int(rng.integers(1, 60)))), gamma)
             for gamma in (0.0, 0.5, 0.9, 0.99, 1.0)]
    cases += [([], 0.99), ([-1.0, -1.0, -1.0], 0.5)]
    return [float(fn(list(rewards), gamma)) for rewards, gamma in cases]


@pytest.mark.exercise("discounted_return", points=1, reference="dlo_course.ddpg.bellman_target")
def test_discounted_return(student):
    got = student.run(probe_discounted_return)
    want = answer_result(GRADING_DIR, "discounted_return", probe_discounted_return)
    assert got == pytest.approx(want, rel=1e-9, abs=1e-12)


def probe_bellman_target(fn):
    gen = torch.Generator().manual_seed(1)
    out = []
    for gamma in (0.99, 0.9, 0.0, 1.0):
        reward = torch.randn(64, 1, generator=gen)
        next_q = torch.randn(64, 1, generator=gen) * 10
        done = (torch.rand(64, 1, generator=gen) < 0.3).float()
        inputs = [t.clone() for t in (reward, next_q, done)]
        got = torch.as_tensor(fn(*inputs, gamma))
        kept = all(torch.equal(a, b) for a, b in zip((reward, next_q, done), inputs))
        out.append({"target": got, "inputs_kept": kept})
    # terminal transitions: the target is the reward alone
    terminal = fn(torch.ones(3, 1), torch.full((3, 1), 100.0), torch.ones(3, 1), 0.99)
    return out, torch.as_tensor(terminal)


@pytest.mark.exercise("bellman_target", points=2, reference="dlo_course.ddpg.bellman_target")
def test_bellman_target(student):
    got, terminal = student.run(probe_bellman_target)
    want, want_terminal = probe_bellman_target(bellman_target)
    for mine, ref in zip(got, want):
        assert mine["target"].shape == (64, 1), f"shape {tuple(mine['target'].shape)}, " \
                                                f"expected (64, 1)"
        torch.testing.assert_close(mine["target"], ref["target"])
        assert mine["inputs_kept"], "the inputs must not be modified"
    torch.testing.assert_close(terminal, want_terminal)


def probe_q_iteration_sweep(fn):
    rng = np.random.default_rng(11)
    out = []
    for n_states, n_actions, gamma in [(7, 2, 0.99), (10, 3, 0.9), (4, 5, 0.0)]:
        q = rng.normal(size=(n_states, n_actions))
        next_state = rng.integers(n_states, size=(n_states, n_actions))
        reward = rng.normal(size=(n_states, n_actions))
        done = (rng.random((n_states, n_actions)) < 0.3).astype(float)
        q_before = q.copy()
        got = np.asarray(fn(q, next_state, reward, done, gamma), dtype=np.float64)
        out.append({"q": got, "q_kept": bool(np.array_equal(q, q_before))})
    return out


@pytest.mark.exercise("q_iteration_sweep", points=2, reference="dlo_course.ddpg.bellman_target")
def test_q_iteration_sweep(student):
    got = student.run(probe_q_iteration_sweep)
    want = answer_result(GRADING_DIR, "q_iteration_sweep", probe_q_iteration_sweep)
    for mine, ref in zip(got, want, strict=True):
        assert mine["q"].shape == ref["q"].shape
        np.testing.assert_allclose(mine["q"], ref["q"], rtol=1e-9, atol=1e-12)
        assert mine["q_kept"], "q must not be modified"
