"""Grading: lesson 12, hindsight relabelling (reference: dlo_course.her).

``relabel`` is compared with the library on fixed inputs (it is given its steps and goal
steps, so its answer is deterministic). ``future_goal_steps``
draws at random, so any correct sampler must pass, whatever generator calls it makes: its
draws are checked for shape, range, reproducibility and uniformity. The uniformity bands are
calibrated: a correct uniform sampler fails the whole test with a probability below 1e-6
(:func:`false_failure_bound` gives about 1e-9), whatever generator calls it makes.

Every input and output crossing to the student's code is plain data (arrays, ints, floats):
the probes below run in the grading sandbox, the checks here.
"""

import math

import numpy as np
import pytest

from dlo_course import her

pytestmark = pytest.mark.notebook("12_hindsight_relabelling")

FIELDS = ("obs", "act", "rew", "next_obs", "done")


# -------------------------------------------------------------- future_goal_steps

SHAPE_CASES = [(1, 1), (1, 5), (4, 1), (7, 3), (60, 4)]  # (episode_length T, k)
SEED_T, SEED_K = 10, 4  # the reproducibility check
UNIFORM_T, UNIFORM_K = 6, 50_000  # the uniformity check: 50 000 goal steps per step t
UNIFORM_SIGMAS = 7.0  # band of each count: +- 7 binomial standard deviations


def probe_future_goal_steps(fn):
    """The student's draws: several shapes, the same and another seed, a large sample."""
    def draw(T, k, seed):
        steps, goal_steps = fn(T, k, np.random.default_rng(seed))
        return {"steps": np.asarray(steps), "goal_steps": np.asarray(goal_steps)}

    shapes = [draw(T, k, 1000 * T + k) for T, k in SHAPE_CASES]
    np.random.seed(123)  # the global generator must not matter
    first = draw(SEED_T, SEED_K, 7)
    np.random.seed(456)
    again, other = draw(SEED_T, SEED_K, 7), draw(SEED_T, SEED_K, 8)
    return {"shapes": shapes, "seeds": [first, again, other],
            "uniform": draw(UNIFORM_T, UNIFORM_K, 2022)}


def check_draw(draw, T, k):
    """Shape, integer type, each step k times, and 0 <= t <= t' < T for every pair."""
    steps, goal_steps = draw["steps"], draw["goal_steps"]
    where = f"T = {T}, k = {k}"
    for name, value in (("steps", steps), ("goal_steps", goal_steps)):
        assert value.shape == (T * k,), f"{where}: {name} of shape {value.shape}, " \
                                        f"expected {(T * k,)}"
        assert value.dtype.kind in "iu", f"{where}: {name} of dtype {value.dtype}, " \
                                         "expected integers"
    # the order of the pairs is free: compare the steps as a multiset
    np.testing.assert_array_equal(np.sort(steps), np.repeat(np.arange(T), k),
                                  err_msg=f"{where}: every step t must appear k times")
    assert np.all(goal_steps >= steps), f"{where}: a goal step t' before its step t"
    assert np.all(goal_steps < T), f"{where}: a goal step t' >= T (outside the episode)"


def pairs(draw):
    """The (t, t') pairs of a draw, in a canonical order."""
    return sorted(zip(draw["steps"].tolist(), draw["goal_steps"].tolist()))


def uniform_bands(T, k):
    """For each step t and goal step t' in [t, T): the expected count k / (T - t) and the
    half-width of the band a correct sampler's count must fall in."""
    bands = {}
    for t in range(T - 1):  # t = T - 1 has one possible goal step: checked by the ranges
        p = 1.0 / (T - t)
        sigma = math.sqrt(k * p * (1 - p))
        for t_goal in range(t, T):
            bands[t, t_goal] = (k * p, UNIFORM_SIGMAS * sigma)
    return bands


@pytest.mark.exercise("future_goal_steps", points=1,
                      reference="dlo_course.her.future_goal_steps")
def test_future_goal_steps(student):
    got = student.run(probe_future_goal_steps)
    for draw, (T, k) in zip(got["shapes"], SHAPE_CASES, strict=True):
        check_draw(draw, T, k)
    first, again, other = got["seeds"]
    for draw in (first, again, other):
        check_draw(draw, SEED_T, SEED_K)
    for name in ("steps", "goal_steps"):
        np.testing.assert_array_equal(first[name], again[name], err_msg=(
            "the same generator seed must give the same draws, whatever the global NumPy "
            "generator does: draw from the rng argument"))
    assert pairs(first) != pairs(other), "another generator seed must give other draws"
    draw = got["uniform"]
    check_draw(draw, UNIFORM_T, UNIFORM_K)
    steps, goal_steps = draw["steps"], draw["goal_steps"]
    for (t, t_goal), (expected, band) in uniform_bands(UNIFORM_T, UNIFORM_K).items():
        count = int(np.sum((steps == t) & (goal_steps == t_goal)))
        assert abs(count - expected) < band, (
            f"step t = {t} of T = {UNIFORM_T}: goal step {t_goal} drawn {count} times in "
            f"{UNIFORM_K}, expected {expected:.0f} +- {band:.0f}: t' must be uniform in [t, T)")


def _chernoff_tail(n, p, q):
    """Upper bound of P(X >= n q) for q > p (or of P(X <= n q) for q < p), X ~ Bin(n, p):
    exp(-n KL(q || p)) (Chernoff-Hoeffding)."""
    if q <= 0.0 or q >= 1.0:
        return (1 - p) ** n if q <= 0.0 else p ** n
    kl = q * math.log(q / p) + (1 - q) * math.log((1 - q) / (1 - p))
    return math.exp(-n * kl)


def false_failure_bound():
    """An upper bound on the probability that a correct, uniform, seeded sampler fails
    :func:`test_future_goal_steps` (union bound over every random check)."""
    bound = 0.0
    for (t, _), (expected, band) in uniform_bands(UNIFORM_T, UNIFORM_K).items():
        n, p = UNIFORM_K, 1.0 / (UNIFORM_T - t)
        bound += _chernoff_tail(n, p, (expected + band) / n)  # count >= expected + band
        bound += _chernoff_tail(n, p, (expected - band) / n)  # count <= expected - band
    # two seeds drawing the same pairs: the pairs are compared as a multiset, i.e. for each
    # step t the multiset of its k goal steps, drawn from c = T - t values. Two independent
    # multisets are equal with probability sum_M P(M)^2 <= max_M P(M) <= k! / c^k.
    same = 1.0
    for t in range(SEED_T):
        c = SEED_T - t
        same *= min(1.0, math.factorial(SEED_K) / c ** SEED_K)
    bound += same
    return bound


# ------------------------------------------------------------------------ relabel

EPISODES = [  # (seed, T, n_nodes, act_dim, k): fixed episodes in the rod's layout
    (0, 6, 2, 3, 3), (1, 9, 4, 3, 2), (2, 1, 1, 2, 3), (3, 5, 6, 3, 2)]
THRESHOLD_MARGIN = 1e-4  # no distance within 0.1 mm of the threshold: float32 cannot flip it


def relabel_cases():
    """Episodes whose P_c wanders by a few cm per step towards no goal in particular, with
    their copies' (steps, goal_steps) in a shuffled order and a threshold that puts some
    copies of t' > t on each side."""
    cases = []
    for seed, T, n_nodes, act_dim, k in EPISODES:
        rng = np.random.default_rng(seed)
        width = 3 * n_nodes
        head = rng.normal(size=(T + 1, 6))  # tip and tip velocity
        achieved = rng.normal(scale=0.3, size=width) + np.cumsum(
            rng.normal(scale=0.03, size=(T + 1, width)), axis=0)
        goal = np.tile(rng.normal(scale=0.3, size=width), (T + 1, 1))
        states = np.concatenate([head, achieved, goal], axis=1).astype(np.float32)
        steps = np.repeat(np.arange(T), k)
        goal_steps = rng.integers(steps, T)
        order = rng.permutation(len(steps))
        steps, goal_steps = steps[order], goal_steps[order]
        next_achieved = states[1:, 6:6 + width].reshape(T, n_nodes, 3)
        distance = her.goal_distance(next_achieved[steps], next_achieved[goal_steps])
        nonzero = np.unique(distance[distance > 0])
        if len(nonzero) >= 2:  # the middle of the widest gap between two copies' distances
            gap = int(np.argmax(np.diff(nonzero)))
            threshold = float(nonzero[gap:gap + 2].mean())
        else:
            threshold = 0.05
        assert np.min(np.abs(distance - threshold)) > THRESHOLD_MARGIN  # the test's own data
        cases.append({"obs": states[:-1], "act": rng.uniform(-1, 1, (T, act_dim)).astype(
            np.float32), "next_obs": states[1:], "steps": steps, "goal_steps": goal_steps,
            "n_nodes": n_nodes, "threshold": threshold})
    return cases


def probe_relabel(fn, cases):
    """The student's copies of each episode, and whether the episode's arrays stayed as
    they were: after the call, and after writing into the copies."""
    results = []
    for case in cases:
        episode = {name: case[name].copy() for name in ("obs", "act", "next_obs")}
        out = fn(episode["obs"], episode["act"], episode["next_obs"], case["steps"].copy(),
                 case["goal_steps"].copy(), case["n_nodes"], case["threshold"])
        result = {"keys": sorted(str(key) for key in out),
                  "fields": {name: np.array(out[name]) for name in FIELDS if name in out}}
        result["untouched"] = all(np.array_equal(episode[n], case[n]) for n in episode)
        for name in ("obs", "act", "next_obs"):
            value = out.get(name)
            if isinstance(value, np.ndarray) and value.flags.writeable:
                value[...] = 1234.5
        result["untouched_after_writing"] = all(np.array_equal(episode[n], case[n])
                                                for n in episode)
        results.append(result)
    return results


@pytest.mark.exercise("relabel", points=3,
                      reference=("dlo_course.her.relabel", "dlo_course.her.goal_distance"))
def test_relabel(student):
    cases = relabel_cases()
    got = student.run(probe_relabel, cases)
    for k, (case, mine) in enumerate(zip(cases, got, strict=True)):
        want = her.relabel(case["obs"], case["act"], case["next_obs"], case["steps"],
                           case["goal_steps"], case["n_nodes"], case["threshold"])
        n, obs_dim = len(case["steps"]), case["obs"].shape[1]
        where = f"case {k} (T = {len(case['obs'])}, {case['n_nodes']} nodes, {n} copies)"
        assert set(mine["keys"]) >= set(FIELDS), f"{where}: the dict must have the keys {FIELDS}"
        for name in FIELDS:
            value = mine["fields"][name]
            assert value.shape == want[name].shape, \
                f"{where}: {name} of shape {value.shape}, expected {want[name].shape}"
            assert value.dtype == np.float32, f"{where}: {name} of dtype {value.dtype}, " \
                                              "expected float32"
        for name in ("obs", "next_obs"):
            np.testing.assert_array_equal(
                mine["fields"][name][:, :obs_dim - 3 * case["n_nodes"]],
                want[name][:, :obs_dim - 3 * case["n_nodes"]],
                err_msg=f"{where}: {name} outside P_d must be the replayed transition's")
            np.testing.assert_array_equal(
                mine["fields"][name][:, obs_dim - 3 * case["n_nodes"]:],
                want[name][:, obs_dim - 3 * case["n_nodes"]:],
                err_msg=f"{where}: P_d of {name} must be the P_c of next_obs[goal_steps]")
        np.testing.assert_array_equal(mine["fields"]["act"], want["act"],
                                      err_msg=f"{where}: act of the replayed transitions")
        np.testing.assert_allclose(mine["fields"]["rew"], want["rew"], rtol=1e-6, atol=1e-7,
                                   err_msg=f"{where}: rew = -goal_distance(P_c of next_obs, goal)")
        np.testing.assert_array_equal(mine["fields"]["done"], want["done"],
                                      err_msg=f"{where}: done = (distance < threshold)")
        assert mine["untouched"], f"{where}: relabel changed the episode's arrays"
        assert mine["untouched_after_writing"], \
            f"{where}: the copies share memory with the episode's arrays"


@pytest.mark.exercise("prediction_successes", points=1)
def test_prediction_successes(written_answer):
    written_answer.check()
