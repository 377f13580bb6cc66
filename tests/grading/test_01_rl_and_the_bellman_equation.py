"""Grading: lesson 1, RL and the Bellman equation (reference: dlo_course.ddpg.bellman_target).

Each ``probe_*`` runs in the sandbox on the student's function (and here on the reference)
and returns plain results; the tests compare them in the grader's own process. The library
has no discounted return nor Q-iteration. The discounted return is checked on rewards drawn
afresh at every grading, against the recursion that defines it (nothing to copy); the
Q-iteration sweep against the grader's own answer (``answers.py``, kept out of the student
bundle, see :func:`dlo_course.grading.bundle.answer_result`).
"""

import random
from pathlib import Path

import numpy as np
import pytest
import torch

from dlo_course.grading.bundle import answer_result
from dlo_course.ddpg import bellman_target

pytestmark = pytest.mark.notebook("01_rl_and_the_bellman_equation")
GRADING_DIR = Path(__file__).resolve().parent


def discounted_return_cases(seed):
    """(rewards, gamma) cases: random rewards of random lengths for five discounts."""
    rng = np.random.default_rng(seed)
    cases = [(rng.normal(size=int(rng.integers(1, 60))).tolist(), gamma)
             for gamma in (0.0, 0.5, 0.9, 0.99, 1.0)]
    return cases + [([-1.0, -1.0, -1.0], 0.5)]


def probe_discounted_return(fn, cases):
    """The return of every suffix of each case's rewards, the empty one last."""
    return [[float(fn(list(rewards[k:]), gamma)) for k in range(len(rewards) + 1)]
            for rewards, gamma in cases]


@pytest.mark.exercise("discounted_return", points=1, reference="dlo_course.ddpg.bellman_target")
def test_discounted_return(student):
    """G of no reward is 0 and G(r_k, r_k+1, ...) = r_k + gamma G(r_k+1, ...), on every
    suffix: that pins G down, on rewards drawn now (a recorded output would be copyable)."""
    cases = discounted_return_cases(random.SystemRandom().randrange(2**32))
    got = student.run(probe_discounted_return, cases)
    for returns, (rewards, gamma) in zip(got, cases, strict=True):
        assert len(returns) == len(rewards) + 1
        assert returns[-1] == pytest.approx(0.0, abs=1e-12), "the return of no reward is 0"
        for k, reward in enumerate(rewards):
            assert returns[k] == pytest.approx(reward + gamma * returns[k + 1], rel=1e-9,
                                               abs=1e-12), \
                f"gamma={gamma}, {len(rewards) - k} rewards: G = {returns[k]!r}, but r + " \
                f"gamma * G(next) = {reward + gamma * returns[k + 1]!r}"


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


@pytest.mark.exercise("prediction_sweeps", points=1)
def test_prediction_sweeps(written_answer):
    written_answer.check()
