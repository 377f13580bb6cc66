"""Grading: lesson 16, robustness and the road to the real robot (references:
dlo_course.randomisation and dlo_course.robustness).

The three exercises are pure functions: each is run on fixed inputs built here (SimParams and
factors, observations and seeded generators, factor ranges) and its results are compared with
the library's on the same inputs, errors included. No simulator runs. The probes below run in
the grading sandbox, the checks here.
"""

import dataclasses

import numpy as np
import pytest

from dlo_course import randomisation, robustness
from dlo_course.simulation import SimParams

pytestmark = pytest.mark.notebook("16_robustness")


def call(fn, *args):
    """(result, None) or (None, the exception's class name)."""
    try:
        return fn(*args), None
    except Exception as err:  # noqa: BLE001
        return None, type(err).__name__


# ------------------------------------------------------------------ scale_params
SCALE_CASES = [
    {"youngs_modulus": 1.3}, {"mass": 0.7}, {"damping": 2.0}, {"edge_damping": 0.5},
    {"youngs_modulus": 0.7, "mass": 1.3, "damping": 0.5}, {}, {"mass": 1},
]
SCALE_BAD = [{"damping": 0.0}, {"damping": -1.0}, {"mass": -0.5}, {"edge_damping": 0.0},
             {"damping": float("nan")}, {"youngs_modulus": float("inf")}, {"length": 1.1},
             {"stiffness": 1.3}, {"gravity": 2.0}]
SCALE_BASES = [dict(), dict(mass=0.3, youngs_modulus=1.0e6, damping=0.02, edge_damping=0.4)]


def probe_scale_params(fn, bases, cases, bad):
    out = {"results": [], "raised": []}
    for base in bases:
        params = SimParams(**base)
        for factors in cases:
            result, error = call(fn, params, dict(factors))
            out["results"].append(error if result is None else dataclasses.asdict(result))
        out["unchanged"] = dataclasses.asdict(params)
    for factors in bad:
        result, error = call(fn, SimParams(), dict(factors))
        out["raised"].append(error)
    return out


@pytest.mark.exercise("scale_params", points=2, reference="dlo_course.randomisation.scale_params")
def test_scale_params(student):
    got = student.run(probe_scale_params, SCALE_BASES, SCALE_CASES, SCALE_BAD)
    results = iter(got["results"])
    for base in SCALE_BASES:
        for factors in SCALE_CASES:
            mine = next(results)
            assert isinstance(mine, dict), f"scale_params(..., {factors}) raised {mine}"
            want = dataclasses.asdict(randomisation.scale_params(SimParams(**base), factors))
            assert mine.keys() == want.keys()
            for key, value in want.items():
                if isinstance(value, float):
                    assert mine[key] == pytest.approx(value, rel=1e-12), f"{factors}: {key}"
                else:
                    assert mine[key] == value, f"{factors}: {key}"
    for factors, raised in zip(SCALE_BAD, got["raised"], strict=True):
        assert raised == "ValueError", f"scale_params(params, {factors}) must raise " \
                                       f"ValueError ({raised})"


# ------------------------------------------------------------------ add_observation_noise
def noise_cases():
    """(obs, n_nodes, std, seed): single observations of 2, 4 and 6 nodes, a batch, a
    float32 observation, and zero noise."""
    rng = np.random.default_rng(16)
    return [
        (rng.normal(size=30), 4, 0.005, 1),
        (rng.normal(size=18), 2, 0.01, 2),
        (rng.normal(size=42), 6, 0.02, 3),
        (rng.normal(size=(5, 30)), 4, 0.003, 4),
        (rng.normal(size=30).astype(np.float32), 4, 0.01, 5),
        (rng.normal(size=30), 4, 0.0, 6),
        (rng.normal(size=(3, 18)), 2, 0.0, 7),
    ]


NOISE_BAD = [(30, 4, -0.01), (30, 4, float("nan")), (30, 2, 0.01), (18, 4, 0.0)]


def probe_add_observation_noise(fn, cases, bad):
    out = {"results": [], "inputs": [], "after": [], "raised": []}
    for obs, n_nodes, std, seed in cases:
        rng = np.random.default_rng(seed)
        given = obs.copy()
        result = fn(given, n_nodes, std, rng)
        out["results"].append(np.asarray(result, dtype=np.float64))
        out["inputs"].append(given)
        out["after"].append(float(rng.random()))  # where the generator was left
    for size, n_nodes, std in bad:
        _, error = call(fn, np.zeros(size), n_nodes, std, np.random.default_rng(0))
        out["raised"].append(error)
    return out


@pytest.mark.exercise("add_observation_noise", points=2,
                      reference="dlo_course.robustness.add_observation_noise")
def test_add_observation_noise(student):
    cases = noise_cases()
    got = student.run(probe_add_observation_noise, cases, NOISE_BAD)
    for k, (obs, n_nodes, std, seed) in enumerate(cases):
        rng = np.random.default_rng(seed)
        want = robustness.add_observation_noise(obs, n_nodes, std, rng)
        where = f"case {k}: {n_nodes} nodes, shape {obs.shape}, std {std}"
        mine = got["results"][k]
        assert mine.shape == want.shape, where
        np.testing.assert_allclose(mine, want, rtol=1e-6, atol=1e-7, err_msg=where)
        np.testing.assert_array_equal(got["inputs"][k], obs, err_msg=f"{where}: obs modified")
        assert got["after"][k] == rng.random(), f"{where}: one draw of the P_c slice's shape " \
                                                "(none for std 0) expected"
    for bad, raised in zip(NOISE_BAD, got["raised"], strict=True):
        assert raised == "ValueError", f"add_observation_noise on {bad} must raise " \
                                       f"ValueError ({raised})"


# ------------------------------------------------------------------ draw_factors
DRAW_CASES = [
    ({"youngs_modulus": (0.7, 1.3)}, 0),
    ({"mass": (0.8, 1.2), "youngs_modulus": (0.7, 1.3)}, 1),  # not in sorted order
    ({"youngs_modulus": (0.7, 1.3), "mass": (0.8, 1.2), "damping": (0.5, 2.0)}, 2),
    ({"edge_damping": (1.0, 1.0), "damping": [0.9, 1.1]}, 3),
    ({}, 4),
]
DRAW_BAD = [{"mass": (1.2, 0.8)}, {"mass": (0.0, 1.0)}, {"damping": (-1.0, 1.0)},
            {"youngs_modulus": (0.7, float("inf"))}, {"stiffness": (0.8, 1.2)},
            {"length": (0.9, 1.1)}]


def probe_draw_factors(fn, cases, bad):
    out = {"results": [], "after": [], "repeat": [], "raised": []}
    for ranges, seed in cases:
        rng = np.random.default_rng(seed)
        result = fn(dict(ranges), rng)
        out["results"].append({str(k): float(v) for k, v in result.items()})
        out["after"].append(float(rng.random()))
        again = fn(dict(ranges), np.random.default_rng(seed))
        out["repeat"].append({str(k): float(v) for k, v in again.items()})
    for ranges in bad:
        _, error = call(fn, dict(ranges), np.random.default_rng(0))
        out["raised"].append(error)
    return out


@pytest.mark.exercise("draw_factors", points=2, reference="dlo_course.randomisation.draw_factors")
def test_draw_factors(student):
    got = student.run(probe_draw_factors, DRAW_CASES, DRAW_BAD)
    for k, (ranges, seed) in enumerate(DRAW_CASES):
        rng = np.random.default_rng(seed)
        want = randomisation.draw_factors(ranges, rng)
        mine = got["results"][k]
        assert sorted(mine) == sorted(want), f"{ranges}: names {sorted(mine)}"
        for name, value in want.items():
            assert mine[name] == pytest.approx(value, rel=1e-12), \
                f"{ranges}, seed {seed}: {name} (names in sorted order, one uniform each)"
        assert got["after"][k] == rng.random(), f"{ranges}: one draw per factor expected"
        assert got["repeat"][k] == mine, f"{ranges}: the same seed must give the same factors"
    for ranges, raised in zip(DRAW_BAD, got["raised"], strict=True):
        assert raised == "ValueError", f"draw_factors({ranges}) must raise ValueError ({raised})"


# ------------------------------------------------------------------ written answers
@pytest.mark.exercise("prediction_robustness", points=1)
def test_prediction_robustness(written_answer):
    written_answer.check()
