import numpy as np
import pytest

from dlo_course.replay_buffer import ReplayBuffer


def fill(buffer: ReplayBuffer, start: int, stop: int) -> None:
    """Add transitions numbered start..stop-1; every field of transition i encodes i."""
    for i in range(start, stop):
        buffer.add(np.full(buffer.obs_dim, i), np.full(buffer.act_dim, -i), float(i),
                   np.full(buffer.obs_dim, i + 0.5), i % 2 == 0)


def test_add_sample_shapes_and_dtypes():
    buffer = ReplayBuffer(obs_dim=4, act_dim=3, capacity=10, seed=0)
    fill(buffer, 0, 6)
    assert len(buffer) == 6
    batch = buffer.sample(5)
    expected = {"obs": (5, 4), "act": (5, 3), "rew": (5,), "next_obs": (5, 4), "done": (5,)}
    assert {k: v.shape for k, v in batch.items()} == expected
    assert all(v.dtype == np.float32 for v in batch.values())
    # the fields of a sampled transition belong together
    i = batch["rew"]
    np.testing.assert_array_equal(batch["obs"][:, 0], i)
    np.testing.assert_array_equal(batch["act"][:, 0], -i)
    np.testing.assert_array_equal(batch["next_obs"][:, 0], i + 0.5)
    np.testing.assert_array_equal(batch["done"], (i % 2 == 0).astype(np.float32))


def test_wrap_around_overwrites_the_oldest():
    buffer = ReplayBuffer(obs_dim=1, act_dim=1, capacity=3, seed=0)
    fill(buffer, 0, 5)
    assert len(buffer) == 3
    # 0, 1, 2 written in rows 0, 1, 2; then 3 and 4 overwrite rows 0 and 1
    np.testing.assert_array_equal(buffer.rew, [3, 4, 2])
    assert set(buffer.sample(200)["rew"]) == {2.0, 3.0, 4.0}


def test_sampling_is_uniform():
    buffer = ReplayBuffer(obs_dim=1, act_dim=1, capacity=4, seed=1)
    fill(buffer, 0, 4)
    counts = np.bincount(buffer.sample(40_000)["rew"].astype(int), minlength=4)
    # binomial std of a count is ~87; 5 sigma
    assert np.all(np.abs(counts - 10_000) < 450), counts


def test_sampling_is_seeded():
    a, b, c = (ReplayBuffer(1, 1, capacity=100, seed=s) for s in (7, 7, 8))
    for buf in (a, b, c):
        fill(buf, 0, 100)
    np.testing.assert_array_equal(a.sample(32)["rew"], b.sample(32)["rew"])
    assert not np.array_equal(a.sample(32)["rew"], c.sample(32)["rew"])


def test_state_round_trip_continues_identically():
    original = ReplayBuffer(obs_dim=2, act_dim=1, capacity=5, seed=3)
    fill(original, 0, 7)  # wrapped
    original.sample(4)  # advance the generator
    restored = ReplayBuffer(obs_dim=2, act_dim=1, capacity=5, seed=999)
    restored.load_state_dict(original.state_dict())
    assert len(restored) == len(original)
    for buf in (original, restored):
        fill(buf, 7, 9)  # the write position was restored too
    for _ in range(3):
        x, y = original.sample(6), restored.sample(6)
        for key in x:
            np.testing.assert_array_equal(x[key], y[key])


def test_errors():
    with pytest.raises(ValueError, match="empty"):
        ReplayBuffer(1, 1, capacity=2).sample(1)
    with pytest.raises(ValueError, match="mismatch"):
        ReplayBuffer(1, 1, capacity=3).load_state_dict(ReplayBuffer(2, 1, capacity=3).state_dict())
