"""Grading: lesson 2, experience replay (reference: dlo_course.replay_buffer.ReplayBuffer).

The statistical checks of ``RingBuffer.sample`` are calibrated: a correct uniform sampler
fails them with a probability below 1e-9 (:func:`false_failure_bound`, checked by
``tests/test_grading_calibration.py``), whatever generator it uses.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from dlo_course.grading.bundle import answer_result
from dlo_course.replay_buffer import ReplayBuffer

pytestmark = pytest.mark.notebook("02_experience_replay")

FIELDS = ("obs", "act", "rew", "next_obs", "done")
GRADING_DIR = Path(__file__).resolve().parent


def probe_stored_done(fn):
    cases = [(a, b) for a in (False, True) for b in (False, True)]
    return [float(fn(a, b)) for a, b in cases] + [float(fn(np.bool_(True), np.bool_(False)))]


@pytest.mark.exercise("stored_done", points=1, reference="dlo_course.trainer.run_episode")
def test_stored_done(student):
    assert student.run(probe_stored_done) == \
        answer_result(GRADING_DIR, "stored_done", probe_stored_done)


# ------------------------------------------------------------------- RingBuffer

CASES = [(5, 3), (5, 5), (5, 13), (1, 4), (64, 200)]  # (capacity, transitions added)
BATCH = 2000  # draws per case: enough to hit every stored row (see false_failure_bound)
UNIFORM_ROWS, UNIFORM_DRAWS, UNIFORM_BAND = 4, 20_000, 400  # |count - 5000| < 400 per row


def fill(buffers, start, stop, obs_dim, act_dim):
    for i in range(start, stop):
        for b in buffers:
            b.add(np.full(obs_dim, i, np.float32), np.full(act_dim, -i, np.float32), float(i),
                  np.full(obs_dim, i + 0.5, np.float32), i % 3 == 0)


def probe_ring_buffer(cls):
    """What a RingBuffer class does: sizes, stored rows, samples (runs in the sandbox)."""
    cases = []
    for capacity, n in CASES:
        buffer = cls(4, 3, capacity, seed=0)
        sizes = []
        for k in range(n):  # add one at a time, checking the size on the way
            fill((buffer,), k, k + 1, 4, 3)
            sizes.append(int(len(buffer)))
        batch = buffer.sample(BATCH)
        cases.append({"sizes": sizes,
                      "fields": {name: np.asarray(getattr(buffer, name)) for name in FIELDS},
                      "keys": sorted(str(k) for k in batch),
                      "batch": {name: np.asarray(batch[name]) for name in FIELDS if name in batch}})
    # reproducible with the buffer's own seed, different with another seed
    a, b, c = (cls(1, 1, 100, seed=s) for s in (7, 7, 8))
    fill((a, b, c), 0, 100, 1, 1)
    np.random.seed(123)  # the global generator must not matter
    first = np.asarray(a.sample(32)["rew"])
    np.random.seed(456)
    seeds = [first, np.asarray(b.sample(32)["rew"]), np.asarray(c.sample(32)["rew"])]
    d = cls(1, 1, UNIFORM_ROWS, seed=1)
    fill((d,), 0, UNIFORM_ROWS, 1, 1)
    return {"cases": cases, "seeds": seeds,
            "uniform": np.asarray(d.sample(UNIFORM_DRAWS)["rew"])}


def check_ring_buffer(got, want):
    """Assert that the probe's results ``got`` (the student's) match ``want`` (the library's
    ReplayBuffer) and that the samples are uniform draws of the stored transitions."""
    for (capacity, n), mine, ref in zip(CASES, got["cases"], want["cases"], strict=True):
        where = f"after {n} adds with capacity {capacity}"
        for k, (size, ref_size) in enumerate(zip(mine["sizes"], ref["sizes"], strict=True)):
            assert size == ref_size, f"len {size} after {k + 1} adds with capacity " \
                                     f"{capacity}, expected {ref_size}"
        for name in FIELDS:  # same rows in the same places as the library's ring
            np.testing.assert_array_equal(mine["fields"][name], ref["fields"][name],
                                          err_msg=f"{name} {where}")
        assert set(mine["keys"]) >= set(FIELDS), f"sample must return the keys {FIELDS}"
        batch = mine["batch"]
        shapes = {"obs": (BATCH, 4), "act": (BATCH, 3), "rew": (BATCH,),
                  "next_obs": (BATCH, 4), "done": (BATCH,)}
        for name, shape in shapes.items():
            value = batch[name]
            assert value.shape == shape, f"{name}: shape {value.shape}, expected {shape}"
            assert value.dtype == np.float32, f"{name}: dtype {value.dtype}, expected float32"
        i = batch["rew"]  # the fields of one sampled row belong to one transition
        np.testing.assert_array_equal(batch["obs"][:, 0], i)
        np.testing.assert_array_equal(batch["act"][:, 0], -i)
        np.testing.assert_array_equal(batch["next_obs"][:, 0], i + 0.5)
        np.testing.assert_array_equal(batch["done"], (i % 3 == 0).astype(np.float32))
        kept = set(range(max(0, n - capacity), n))  # only the last `capacity` transitions
        drawn = set(i.astype(int).tolist())
        assert drawn <= kept, f"sampled a transition that is not stored ({where})"
        assert drawn == kept, f"{BATCH} uniform draws should hit every stored transition " \
                              f"({where}); missed {sorted(kept - drawn)[:10]}"
    first, again, other = got["seeds"]
    np.testing.assert_array_equal(first, again, err_msg="sample must be reproducible with the "
                                  "buffer's seed, whatever the global NumPy generator does")
    assert not np.array_equal(first, other), "another seed must give other samples"
    counts = np.bincount(got["uniform"].astype(int), minlength=UNIFORM_ROWS)
    expected = UNIFORM_DRAWS / UNIFORM_ROWS
    assert np.all(np.abs(counts - expected) < UNIFORM_BAND), \
        f"draw counts {counts} of {UNIFORM_ROWS} transitions are not uniform"


def _log_binomial_pmf(k, n, p):
    return (math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)
            + k * math.log(p) + (n - k) * math.log1p(-p))


def false_failure_bound():
    """An upper bound on the probability that a correct, uniform, seeded sampler fails
    :func:`check_ring_buffer` (union bound over every random check)."""
    bound = 0.0
    for capacity, n in CASES:  # some stored row never drawn in BATCH draws
        m = min(capacity, n)
        bound += m * (1 - 1 / m) ** BATCH if m > 1 else 0.0
    # one of UNIFORM_ROWS counts outside the band (exact binomial tails)
    p, mean = 1 / UNIFORM_ROWS, UNIFORM_DRAWS / UNIFORM_ROWS
    tail = sum(math.exp(_log_binomial_pmf(k, UNIFORM_DRAWS, p)) for k in range(UNIFORM_DRAWS + 1)
               if abs(k - mean) >= UNIFORM_BAND)
    bound += UNIFORM_ROWS * tail
    bound += 100.0 ** -32  # two different seeds giving the same 32 draws out of 100
    return bound


@pytest.mark.exercise("RingBuffer", points=3, reference="dlo_course.replay_buffer.ReplayBuffer")
def test_ring_buffer(student):
    check_ring_buffer(student.run(probe_ring_buffer), probe_ring_buffer(ReplayBuffer))
