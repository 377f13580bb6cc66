"""Shared fixtures. Simulator tests are sized for 2 cores: a handful of actions each."""

from __future__ import annotations

import numpy as np
import pytest

import dlo_course  # noqa: F401  (registers DLOShape-v0)
from dlo_course.env import DLOShapeEnv


@pytest.fixture
def far_goals():
    """Two goal sets for 4 nodes, far from the rod, so an episode never terminates early."""
    rng = np.random.default_rng(0)
    return np.array([[1.0, 0.3, 0.5], [1.0, 0.3, 0.7], [1.0, 0.3, 0.9], [1.0, 0.3, 1.1]]) \
        + rng.normal(0, 0.01, size=(3, 4, 3))


@pytest.fixture
def make_env():
    """Build environments and close them at the end of the test."""
    envs = []

    def _make(**kwargs):
        env = DLOShapeEnv(**kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()
