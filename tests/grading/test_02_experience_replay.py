"""Grading: lesson 2, experience replay (reference: dlo_course.replay_buffer.ReplayBuffer)."""

import numpy as np
import pytest

from dlo_course.replay_buffer import ReplayBuffer

pytestmark = pytest.mark.notebook("02_experience_replay")

FIELDS = ("obs", "act", "rew", "next_obs", "done")


@pytest.mark.exercise("stored_done", points=1)
def test_stored_done(exercise):
    # What the trainer stores: done = terminated (see ReplayBuffer.add and trainer.run_episode)
    for terminated in (False, True):
        for truncated in (False, True):
            assert float(exercise(terminated, truncated)) == float(terminated)
    assert float(exercise(np.bool_(True), np.bool_(False))) == 1.0


def fill(buffers, start, stop, obs_dim, act_dim):
    for i in range(start, stop):
        for b in buffers:
            b.add(np.full(obs_dim, i, np.float32), np.full(act_dim, -i, np.float32), float(i),
                  np.full(obs_dim, i + 0.5, np.float32), i % 3 == 0)


@pytest.mark.exercise("RingBuffer", points=3)
def test_ring_buffer(exercise):
    RingBuffer = exercise
    for capacity, n in [(5, 3), (5, 5), (5, 13), (1, 4), (64, 200)]:
        mine, library = RingBuffer(4, 3, capacity, seed=0), ReplayBuffer(4, 3, capacity, seed=0)
        for k in range(n):  # add one at a time, checking the size on the way
            fill((mine, library), k, k + 1, 4, 3)
            assert len(mine) == len(library), f"len after {k + 1} adds with capacity {capacity}"
        for name in FIELDS:  # same rows in the same places as the library's ring
            np.testing.assert_array_equal(getattr(mine, name), getattr(library, name),
                                          err_msg=f"{name} after {n} adds, capacity {capacity}")
        batch = mine.sample(400)
        assert set(batch) >= set(FIELDS), f"sample must return the keys {FIELDS}"
        shapes = {"obs": (400, 4), "act": (400, 3), "rew": (400,), "next_obs": (400, 4),
                  "done": (400,)}
        for name, shape in shapes.items():
            value = np.asarray(batch[name])
            assert value.shape == shape, f"{name}: shape {value.shape}, expected {shape}"
            assert value.dtype == np.float32, f"{name}: dtype {value.dtype}, expected float32"
        i = batch["rew"]  # the fields of one sampled row belong to one transition
        np.testing.assert_array_equal(batch["obs"][:, 0], i)
        np.testing.assert_array_equal(batch["act"][:, 0], -i)
        np.testing.assert_array_equal(batch["next_obs"][:, 0], i + 0.5)
        np.testing.assert_array_equal(batch["done"], (i % 3 == 0).astype(np.float32))
        kept = set(range(max(0, n - capacity), n))  # only the last `capacity` transitions
        assert set(i.astype(int)) <= kept, "sampled a transition that is not stored"
        if len(kept) <= 64:
            assert set(i.astype(int)) == kept, "400 uniform draws should hit every transition"
    # reproducible with the buffer's own seed, different with another seed
    a, b, c = (RingBuffer(1, 1, 100, seed=s) for s in (7, 7, 8))
    fill((a, b, c), 0, 100, 1, 1)
    np.random.seed(123)  # the global generator must not matter
    first = a.sample(32)["rew"]
    np.random.seed(456)
    np.testing.assert_array_equal(first, b.sample(32)["rew"])
    assert not np.array_equal(first, c.sample(32)["rew"])
    # roughly uniform: 4 transitions, 20 000 draws
    d = RingBuffer(1, 1, 4, seed=1)
    fill((d,), 0, 4, 1, 1)
    counts = np.bincount(np.asarray(d.sample(20_000)["rew"]).astype(int), minlength=4)
    assert np.all(np.abs(counts - 5000) < 400), f"draw counts {counts} are not uniform"
