"""Ornstein–Uhlenbeck exploration noise.

DDPG's actor is deterministic: in a given state it always proposes the same action, so on its
own it would never try anything new. During training we add noise to its actions. The paper
(following Lillicrap et al., 2015) uses an Ornstein–Uhlenbeck (OU) process, which is
*temporally correlated*: each noise value is pulled back towards ``mu`` but remembers the
previous one,

    x_{k+1} = x_k + theta * (mu - x_k) * dt + sigma * sqrt(dt) * N(0, I).

For a robot commanded in velocity this matters: independent noise at every step mostly cancels
out (the tip jitters in place), while correlated noise pushes the tip in one direction for a
while, so it actually explores the workspace. The process restarts from ``mu`` at the start of
every episode (:meth:`OUNoise.reset`).

With theta = 0.15, dt = 1 the noise decorrelates over about 1/theta ~ 7 steps and its
stationary standard deviation is sigma / sqrt(theta * (2 - theta)) ~ 1.9 sigma: 0.57 for
sigma = 0.3, in the units of the normalised action [-1, 1]. That is strong exploration: the
noisy action often leaves [-1, 1] and is clipped.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class OUNoise:
    """Ornstein–Uhlenbeck process with its own seeded random generator.

    Args:
        size: dimension of the noise vector (the action dimension, 3 for the robot).
        theta: how fast the noise is pulled back to ``mu`` (the paper's code: 0.15).
        sigma: scale of the random kicks (the paper's code: 0.3).
        mu: value the process reverts to (0: no preferred direction).
        dt: time step of the discretisation; 1 means "one environment step".
        seed: seed of the noise's own generator, so each MPI rank explores differently and a
            resumed run draws the same noise as an uninterrupted one.
    """

    def __init__(self, size: int, theta: float = 0.15, sigma: float = 0.3, mu: float = 0.0,
                 dt: float = 1.0, seed: int | None = None) -> None:
        self.size, self.theta, self.sigma, self.mu, self.dt = int(size), theta, sigma, mu, dt
        self.rng = np.random.default_rng(seed)
        self.state = np.full(self.size, mu, dtype=np.float64)

    def reset(self) -> None:
        """Restart the process at ``mu`` (called at the start of every episode)."""
        self.state = np.full(self.size, self.mu, dtype=np.float64)

    def sample(self) -> np.ndarray:
        """Advance the process by one step and return the new value, shape (size,), float32."""
        drift = self.theta * (self.mu - self.state) * self.dt
        kick = self.sigma * np.sqrt(self.dt) * self.rng.standard_normal(self.size)
        self.state = self.state + drift + kick
        return self.state.astype(np.float32)

    def state_dict(self) -> dict[str, Any]:
        return {"state": self.state.copy(), "rng_state": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.state = np.asarray(state["state"], dtype=np.float64).copy()
        self.rng.bit_generator.state = state["rng_state"]
