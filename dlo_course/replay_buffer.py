"""The replay buffer: the agent's memory of past transitions.

DDPG is off-policy: it can learn from transitions gathered by older versions of its policy.
The buffer stores the last ``capacity`` transitions (s, a, r, s', d) and hands out random
batches of them. Sampling at random, instead of learning from the last few steps in order,
breaks the strong correlation between consecutive transitions (Section IV of the paper,
"Training procedure").

The storage is a ring: five preallocated NumPy arrays and a write index that wraps around, so
that once the buffer is full the oldest transition is overwritten first. Nothing is ever
appended or deleted, so adding a transition costs the same at step 10 and at step 10 million.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class ReplayBuffer:
    """Fixed-size ring buffer of transitions, sampled uniformly.

    Args:
        obs_dim: length of an observation vector (18, 30 or 42 for 2, 4 or 6 rod nodes).
        act_dim: length of an action vector (3: the gripper tip velocity).
        capacity: how many transitions are kept; the paper keeps 50 000.
        seed: seed of the buffer's own random generator. The buffer owns its generator so
            that its draws do not depend on who else uses NumPy's global one, and so that its
            state can be saved and restored with the buffer (exact resume of a training run).

    Arrays (``N = capacity``), all float32:
        ``obs`` (N, obs_dim), ``act`` (N, act_dim), ``rew`` (N,), ``next_obs`` (N, obs_dim),
        ``done`` (N,) with 1.0 where the episode *terminated* at that transition.
    """

    def __init__(self, obs_dim: int, act_dim: int, capacity: int = 50_000,
                 seed: int | None = None) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        self.obs_dim, self.act_dim, self.capacity = int(obs_dim), int(act_dim), int(capacity)
        self.obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.act = np.zeros((capacity, act_dim), dtype=np.float32)
        self.rew = np.zeros(capacity, dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.done = np.zeros(capacity, dtype=np.float32)
        self._next = 0  # the row the next transition is written to
        self._size = 0  # how many rows hold a transition
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return self._size

    def add(self, obs: np.ndarray, act: np.ndarray, rew: float, next_obs: np.ndarray,
            done: bool | float) -> None:
        """Store one transition, overwriting the oldest one when the buffer is full.

        Args:
            obs: (obs_dim,) observation s in which the action was taken.
            act: (act_dim,) action a actually sent to the environment (noise included).
            rew: reward r received for it.
            next_obs: (obs_dim,) observation s' after the action.
            done: True only if s' is terminal (the goal was reached). An episode cut by a
                time limit is *not* done: s' still has a future, and the Bellman target must
                keep bootstrapping from it.
        """
        i = self._next
        self.obs[i] = obs
        self.act[i] = act
        self.rew[i] = rew
        self.next_obs[i] = next_obs
        self.done[i] = float(done)
        self._next = (i + 1) % self.capacity
        self._size = min(self._size + 1, self.capacity)

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        """Draw ``batch_size`` stored transitions uniformly at random, with replacement.

        With replacement, because it is simpler and cheaper, and with 50 000 stored
        transitions a batch of 128 almost never holds the same one twice.

        Returns:
            A dict of float32 arrays (``B = batch_size``): ``obs`` (B, obs_dim),
            ``act`` (B, act_dim), ``rew`` (B,), ``next_obs`` (B, obs_dim), ``done`` (B,).
        """
        if self._size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        idx = self.rng.integers(0, self._size, size=batch_size)
        return {
            "obs": self.obs[idx],
            "act": self.act[idx],
            "rew": self.rew[idx],
            "next_obs": self.next_obs[idx],
            "done": self.done[idx],
        }

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue exactly where this buffer is: contents, write
        position and the generator's state. Only the filled rows are saved."""
        n = self._size
        return {
            "obs_dim": self.obs_dim, "act_dim": self.act_dim, "capacity": self.capacity,
            "next": self._next, "size": n,
            "obs": self.obs[:n].copy(), "act": self.act[:n].copy(), "rew": self.rew[:n].copy(),
            "next_obs": self.next_obs[:n].copy(), "done": self.done[:n].copy(),
            "rng_state": self.rng.bit_generator.state,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a buffer saved by :meth:`state_dict` (same dimensions and capacity)."""
        shape = (state["obs_dim"], state["act_dim"], state["capacity"])
        if shape != (self.obs_dim, self.act_dim, self.capacity):
            raise ValueError(f"buffer shape mismatch: saved (obs_dim, act_dim, capacity) = "
                             f"{shape}, this buffer has "
                             f"{(self.obs_dim, self.act_dim, self.capacity)}")
        n = int(state["size"])
        # Rows [0, n) are always the filled ones: the ring only wraps once it is full.
        for name in ("obs", "act", "rew", "next_obs", "done"):
            getattr(self, name)[:n] = state[name]
        self._size, self._next = n, int(state["next"])
        self.rng.bit_generator.state = state["rng_state"]
