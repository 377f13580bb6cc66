"""Grading: lesson 12, hindsight relabelling (reference: dlo_course.her).

``relabel`` is compared with the library on fixed inputs (it is given its steps and goal
steps, so its answer is deterministic).

Every input and output crossing to the student's code is plain data (arrays, ints, floats):
the probes below run in the grading sandbox, the checks here.
"""

import numpy as np
import pytest

from dlo_course import her

pytestmark = pytest.mark.notebook("12_hindsight_relabelling")

FIELDS = ("obs", "act", "rew", "next_obs", "done")


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
