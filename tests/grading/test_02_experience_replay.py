"""Grading: lesson 2, experience replay (reference: dlo_course.replay_buffer.ReplayBuffer, fed
the done flag dlo_course.trainer stores: ``terminated``).

``RingBuffer.add`` receives both flags of a step, ``terminated`` and ``truncated``, and decides
what done flag to store; the flags of every transition are drawn afresh at each grading, so
no recorded output can stand in for the decision. The statistical checks of
``RingBuffer.sample`` are calibrated: a correct uniform sampler fails them with a probability
below 1e-9 (:func:`false_failure_bound`, checked by ``tests/test_grading_calibration.py``),
whatever generator it uses.
"""

import math
import random

import numpy as np
import pytest

from dlo_course.replay_buffer import ReplayBuffer

pytestmark = pytest.mark.notebook("02_experience_replay")

FIELDS = ("obs", "act", "rew", "next_obs", "done")


class LibraryRing(ReplayBuffer):
    """The library's buffer behind the exercise's interface: given both flags of a step, it
    stores what ``dlo_course.trainer.run_episode`` passes to ``ReplayBuffer.add``."""

    def add(self, obs, act, rew, next_obs, terminated, truncated):
        super().add(obs, act, rew, next_obs, terminated)


# ------------------------------------------------------------------- RingBuffer

CASES = [(5, 3), (5, 5), (5, 13), (1, 4), (64, 200)]  # (capacity, transitions added)
BATCH = 2000  # draws per case: enough to hit every stored row (see false_failure_bound)
UNIFORM_ROWS, UNIFORM_DRAWS, UNIFORM_BAND = 4, 20_000, 400  # |count - 5000| < 400 per row


def step_flags(seed, n):
    """(terminated, truncated) of n transitions in a random order: the four combinations
    once each (when n >= 4), the rest random; every other pair as NumPy booleans, as some
    environments return them."""
    rng = np.random.default_rng(seed)
    flags = [(False, False), (True, False), (False, True), (True, True)]
    flags += [(bool(a), bool(b)) for a, b in rng.random((max(n - 4, 0), 2)) < 0.4]
    rng.shuffle(flags)
    return [(np.bool_(a), np.bool_(b)) if k % 2 else (a, b) for k, (a, b) in enumerate(flags[:n])]


def fill(buffers, start, stop, obs_dim, act_dim, flags=None):
    for i in range(start, stop):
        terminated, truncated = flags[i] if flags else (i % 3 == 0, i % 4 == 3)
        for b in buffers:
            b.add(np.full(obs_dim, i, np.float32), np.full(act_dim, -i, np.float32), float(i),
                  np.full(obs_dim, i + 0.5, np.float32), terminated, truncated)


def probe_ring_buffer(cls, seed=0):
    """What a RingBuffer class does: sizes, stored rows, samples (runs in the sandbox). The
    transitions' flags come from ``seed``."""
    cases = []
    for capacity, n in CASES:
        buffer = cls(4, 3, capacity, seed=0)
        flags = step_flags(seed + capacity * 1000 + n, n)
        sizes = []
        for k in range(n):  # add one at a time, checking the size on the way
            fill((buffer,), k, k + 1, 4, 3, flags)
            sizes.append(int(len(buffer)))
        batch = buffer.sample(BATCH)
        cases.append({"sizes": sizes, "terminated": [bool(a) for a, _ in flags],
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
        stored, ref_stored = mine["fields"]["done"], ref["fields"]["done"]
        if stored.shape == ref_stored.shape and not np.array_equal(stored, ref_stored):
            rows = [k for k in range(len(stored)) if stored[k] != ref_stored[k]][:5]
            raise AssertionError(
                f"done {where}: rows {rows} hold {stored[rows].tolist()}, expected "
                f"{ref_stored[rows].tolist()}. Store d = 1.0 only for a transition that "
                f"terminated: a truncated one (cut by a time limit) still has a future, "
                f"and its Bellman target must keep bootstrapping")
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
        terminated = np.asarray(ref["terminated"], dtype=np.float32)
        np.testing.assert_array_equal(batch["done"], terminated[i.astype(int)],
                                      err_msg="a sampled row's done is not its transition's")
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


@pytest.mark.exercise("RingBuffer", points=4, reference="dlo_course.replay_buffer.ReplayBuffer")
def test_ring_buffer(student):
    seed = random.SystemRandom().randrange(2**31)
    check_ring_buffer(student.run(probe_ring_buffer, seed), probe_ring_buffer(LibraryRing, seed))


@pytest.mark.exercise("prediction_ring", points=1)
def test_prediction_ring(written_answer):
    written_answer.check()
