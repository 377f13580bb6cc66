"""dlo_course.robustness and dlo_course.randomisation: a perturbed world really is perturbed
in PyBullet, nonsense values are refused, the observation noise touches only P_c (seeded, zero noise the identity), domain
randomisation is seeded and reaches the scene, and `dlo-course evaluate` takes both."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from click.testing import CliRunner

from dlo_course import robustness
from dlo_course.cli import main
from dlo_course.randomisation import draw_factors, scale_params, validate_factors, validate_ranges
from dlo_course.robustness import ObservationNoise, add_observation_noise
from dlo_course.simulation import RodScene, SimParams
from dlo_course.task import ObservationLayout

SETTLE_STEPS = 10  # 30 ms: the rod, released straight, compresses under its own weight


def settling_drop(params: SimParams) -> float:
    """Mean vertical displacement (m) of the rod's nodes over its first 30 ms in the scene."""
    scene = RodScene(params)
    try:
        before = scene.node_positions()
        scene.step_physics(SETTLE_STEPS)
        return float((scene.node_positions() - before)[:, 2].mean())
    finally:
        scene.close()


@pytest.fixture(scope="module")
def nominal_drop():
    return settling_drop(SimParams())


# ------------------------------------------------------------------ model mismatch
def test_scale_params_multiplies_only_the_named_fields():
    base = SimParams()
    scaled = scale_params(base, {"youngs_modulus": 1.3, "mass": 0.7, "damping": 2.0})
    assert scaled.youngs_modulus == pytest.approx(1.3 * base.youngs_modulus)
    assert scaled.mass == pytest.approx(0.7 * base.mass)
    assert scaled.damping == pytest.approx(2.0 * base.damping)
    assert scaled.with_(youngs_modulus=base.youngs_modulus, mass=base.mass,
                        damping=base.damping) == base
    assert scale_params(base, {}) is base
    # The default rod has no edge dampers (the authors'): a factor scales a base value.
    assert scale_params(base, {"edge_damping": 0.5}).edge_damping == 0.0
    damped = SimParams(edge_damping=1.0)
    assert scale_params(damped, {"edge_damping": 0.5}).edge_damping == pytest.approx(0.5)


@pytest.mark.parametrize("factors, message", [
    ({"mass": 0.0}, "positive"), ({"youngs_modulus": -1.3}, "positive"),
    ({"damping": float("nan")}, "positive"), ({"mass": float("inf")}, "positive"),
    ({"stiffness": 1.3}, "unknown parameter 'stiffness'"), ({"length": 1.1}, "unknown"),
    ({"mass": "heavy"}, "must be a number"),
])
def test_nonsense_factors_are_refused(factors, message):
    with pytest.raises(ValueError, match=message):
        validate_factors(factors)
    with pytest.raises(ValueError, match=message):
        scale_params(SimParams(), factors)


def test_parse_perturbation():
    assert robustness.parse_perturbation("youngs_modulus=1.3") == ("youngs_modulus", 1.3)
    assert robustness.parse_perturbation(" mass = 0.7") == ("mass", 0.7)
    for text in ("mass", "mass=", "mass=x", "mass=0", "mass=-2", "colour=1.1"):
        with pytest.raises(ValueError):
            robustness.parse_perturbation(text)


@pytest.mark.parametrize("factors, low, high", [
    ({"youngs_modulus": 0.5}, 1.6, 2.4),  # half as stiff: the rod compresses twice as much
    ({"mass": 2.0}, 1.6, 2.4),  # twice as heavy: likewise
])
def test_the_scaled_rod_settles_differently_in_pybullet(nominal_drop, factors, low, high):
    drop = settling_drop(scale_params(SimParams(), factors))
    assert nominal_drop < 0 and drop < 0
    assert low < drop / nominal_drop < high


def test_the_scaled_damping_reaches_pybullet(nominal_drop):
    drop = settling_drop(scale_params(SimParams(), {"damping": 3.0}))
    assert abs(drop / nominal_drop - 1) > 0.1


# ------------------------------------------------------------------ sensing noise
class FakeRod(gym.Env):
    """A stand-in for DLOShape-v0 with 4 nodes: fixed observations, reward and info, so the
    wrapper can be checked without the simulator."""

    n_nodes = 4

    def __init__(self):
        self.observation_space = gym.spaces.Box(-10, 10, (30,), np.float32)
        self.action_space = gym.spaces.Box(-1, 1, (3,), np.float32)
        self.obs = np.linspace(-1, 1, 30).astype(np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.obs.copy(), {"distance": 0.2}

    def step(self, action):
        return self.obs.copy(), -0.2, False, False, {"distance": 0.2}


def test_noise_touches_only_the_current_node_positions():
    env = ObservationNoise(FakeRod(), std=0.01, seed=3)
    obs, info = env.reset()
    clean = env.unwrapped.obs
    part = ObservationLayout(4).current
    assert part == slice(6, 18)
    changed = obs != clean
    assert changed[part].all() and not changed[:6].any() and not changed[18:].any()
    assert np.std(obs[part] - clean[part]) < 0.05
    obs, reward, terminated, truncated, info = env.step(np.zeros(3))
    assert (obs[part] != clean[part]).all() and (obs[18:] == clean[18:]).all()
    # The reward, the termination and the info are the true state's.
    assert (reward, terminated, truncated, info) == (-0.2, False, False, {"distance": 0.2})
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)


def test_noise_is_seeded_and_zero_noise_is_the_identity():
    a, b = ObservationNoise(FakeRod(), 0.01, seed=7), ObservationNoise(FakeRod(), 0.01, seed=7)
    first = [a.reset()[0], a.step(np.zeros(3))[0]]
    np.testing.assert_array_equal(first, [b.reset()[0], b.step(np.zeros(3))[0]])
    assert not np.array_equal(first[0], first[1])  # a fresh draw at every observation
    np.testing.assert_array_equal(a.reset(seed=1)[0], b.reset(seed=1)[0])  # reseeded
    other = ObservationNoise(FakeRod(), 0.01, seed=8).reset()[0]
    assert not np.array_equal(other, first[0])
    clean = ObservationNoise(FakeRod(), 0.0, seed=7)
    np.testing.assert_array_equal(clean.reset()[0], FakeRod().obs)
    np.testing.assert_array_equal(clean.step(np.zeros(3))[0], FakeRod().obs)


def test_add_observation_noise_on_batches_and_its_errors():
    obs = np.zeros((5, 18))
    noisy = add_observation_noise(obs, 2, 0.1, np.random.default_rng(0))
    assert (noisy[:, 6:12] != 0).all() and (noisy[:, :6] == 0).all() and (noisy[:, 12:] == 0).all()
    assert (obs == 0).all()  # a copy
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    np.testing.assert_array_equal(add_observation_noise(obs, 2, 0.0, rng), obs)
    assert rng.bit_generator.state == state  # zero noise draws nothing
    for std in (-0.01, float("nan")):
        with pytest.raises(ValueError, match=">= 0"):
            add_observation_noise(obs, 2, std, rng)
        with pytest.raises(ValueError, match=">= 0"):
            ObservationNoise(FakeRod(), std)
    with pytest.raises(ValueError, match="components"):
        add_observation_noise(obs, 4, 0.1, rng)


# ------------------------------------------------------------------ domain randomisation
def test_draw_factors_is_uniform_in_the_ranges_and_seeded():
    ranges = {"mass": (0.8, 1.2), "youngs_modulus": [0.7, 1.3]}
    draws = [draw_factors(ranges, np.random.default_rng(s)) for s in range(200)]
    for name, (low, high) in validate_ranges(ranges).items():
        values = np.array([d[name] for d in draws])
        assert low <= values.min() and values.max() <= high
        assert abs(values.mean() - (low + high) / 2) < 0.05
    reordered = {"youngs_modulus": [0.7, 1.3], "mass": (0.8, 1.2)}
    assert draw_factors(reordered, np.random.default_rng(4)) == draws[4]
    assert draw_factors({"mass": [1.0, 1.0]}, np.random.default_rng(0)) == {"mass": 1.0}


@pytest.mark.parametrize("ranges, message", [
    ({"mass": [1.2, 0.8]}, "empty"), ({"mass": [0.0, 1.0]}, "positive"),
    ({"mass": [0.8]}, "two factors"), ({"mass": 1.0}, "two factors"),
    ({"stiffness": [0.8, 1.2]}, "unknown"),
])
def test_bad_ranges_are_refused(ranges, message):
    with pytest.raises(ValueError, match=message):
        validate_ranges(ranges)


@pytest.mark.slow
def test_domain_randomisation_in_the_environment(make_env):
    base = make_env(n_nodes=4, goals="small-test")
    assert base.randomize == {} and base.sim_factors == {}  # off by default
    env = make_env(n_nodes=4, goals="small-test", randomize={"mass": [0.5, 0.6],
                                                             "youngs_modulus": [1.2, 1.3]})
    assert env.scene.params == SimParams()
    _, info = env.reset(seed=5)
    factors = dict(env.sim_factors)
    assert 0.5 <= factors["mass"] <= 0.6 and 1.2 <= factors["youngs_modulus"] <= 1.3
    assert env.scene.params.mass == pytest.approx(0.2 * factors["mass"])
    assert env.scene.params.youngs_modulus == pytest.approx(2.5e6 * factors["youngs_modulus"])
    assert env.params == SimParams()  # the nominal values stay the reference
    assert info["goal_index"] == base.reset(seed=5)[1]["goal_index"]  # same goals as without
    env.reset(seed=6)
    assert env.sim_factors != factors
    env.reset(seed=5)
    assert env.sim_factors == factors  # deterministic given the seed
    with pytest.raises(ValueError, match="empty"):
        make_env(n_nodes=4, randomize={"mass": [2.0, 1.0]})


def test_domain_randomisation_through_the_training_configuration():
    from dlo_course.config import TrainConfig
    from dlo_course.trainer import make_env

    env = make_env(TrainConfig(env_kwargs={"n_nodes": 2, "randomize": {"damping": [0.5, 2]}}))
    try:
        assert env.unwrapped.randomize == {"damping": (0.5, 2.0)}
    finally:
        env.close()


# ------------------------------------------------------------------ the command line
@pytest.mark.parametrize("args, message", [
    (["--perturb", "stiffness=1.3"], "unknown parameter"),
    (["--perturb", "mass=0"], "positive"),
    (["--perturb", "mass=-0.5"], "positive"),
    (["--perturb", "mass"], "NAME=FACTOR"),
    (["--obs-noise", "-0.01"], ">= 0"),
])
def test_evaluate_refuses_nonsense_perturbations(args, message):
    result = CliRunner().invoke(main, ["evaluate", "--controller", "jacobian", *args])
    assert result.exit_code == 2, result.output
    assert message in result.output and "Traceback" not in result.output


def test_evaluate_in_a_perturbed_world(tmp_path):
    out = tmp_path / "perturbed.json"
    result = CliRunner().invoke(main, [
        "evaluate", "--controller", "jacobian", "--database", "small-test", "--episodes", "1",
        "--max-steps", "2", "--perturb", "youngs_modulus=1.3", "--perturb", "mass=0.7",
        "--obs-noise", "0.005", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "perturbed: youngs_modulus x 1.3, mass x 0.7, noise std 0.005 m on P_c" \
        in result.output
    data = json.loads(out.read_text())
    assert data["perturbation"] == {"factors": {"youngs_modulus": 1.3, "mass": 0.7},
                                    "obs_noise": 0.005}
    assert data["summary"]["episodes"] == 1 and data["episodes"][0]["steps"] <= 2


def test_results_files_table_and_plot(tmp_path):
    def record(controller, parameter, value, done):
        n = 10
        summary = {"episodes": n, "done_percent": 10.0 * done, "done_ci_low": 0.0,
                   "done_ci_high": 100.0, "mean_distance": 0.04}
        return {"controller": controller, "parameter": parameter, "value": value,
                "episodes": n, "seed": 0, "summaries": {"0.05": summary, "0.03": summary}}

    for r in (record("nodes4", "nominal", 1.0, 9), record("nodes4", "mass", 1.3, 7),
              record("nodes4", "obs_noise", 0.01, 5)):
        path = robustness.setting_file(tmp_path, r["controller"], r["parameter"], r["value"])
        path.write_text(json.dumps(r))
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "nodes4_mass_1.3.json", "nodes4_nominal.json", "nodes4_obs_noise_0.01.json"]
    results = robustness.load_results(tmp_path)
    curves = robustness.curves(results)
    assert [row[:2] for row in curves[("nodes4", "mass")]] == [(1.0, 90.0), (1.3, 70.0)]
    assert [row[:2] for row in curves[("nodes4", "obs_noise")]] == [(0.0, 90.0), (0.01, 50.0)]
    low, high = curves[("nodes4", "mass")][1][2:4]
    assert low < 70 < high
    table = robustness.results_table(results)
    assert "mass x 1.3" in table and "std 10 mm" in table and "none (training world)" in table
    import matplotlib

    matplotlib.use("Agg")
    robustness.plot_results(results, tmp_path / "plot.png")
    assert (tmp_path / "plot.png").stat().st_size > 1000


def _paired_record(parameter, value, done, goals):
    episodes = [{"episode": i, "goal_index": g, "done": bool(d), "final_distance": 0.04,
                 "steps": 5, "start_distance": 0.1} for i, (g, d) in enumerate(zip(goals, done))]
    return {"controller": "nodes4", "parameter": parameter, "value": value,
            "episodes": len(done), "seed": 0, "summaries": {}, "records": {"0.05": episodes}}


def test_a_paired_difference_sees_what_two_wilson_intervals_cannot():
    goals = list(range(100))
    nominal = _paired_record("nominal", 1.0, [1] * 80 + [0] * 20, goals)
    # The same 80 goals reached, minus 8 of them: 72% against 80%, eight episodes changed.
    worse = _paired_record("mass", 1.3, [1] * 72 + [0] * 28, goals)
    diff, low, high, discordant = robustness.paired_difference(worse, nominal)
    assert diff == pytest.approx(-8.0) and discordant == 8
    assert low < -8 < high < 0  # told apart: no episode got better
    from dlo_course.evaluation import wilson_interval

    assert wilson_interval(72, 100)[1] > wilson_interval(80, 100)[0]  # the intervals overlap
    # The same done % from different episodes: no change told apart.
    swapped = _paired_record("mass", 0.7, [0] * 8 + [1] * 80 + [0] * 12, goals)
    diff, low, high, discordant = robustness.paired_difference(swapped, nominal)
    assert diff == 0 and discordant == 16 and low < 0 < high
    # No episode changed: 100 episodes still leave a few points either way, not a certainty.
    diff, low, high, discordant = robustness.paired_difference(nominal, nominal)
    assert diff == 0 and discordant == 0 and -6 < low < -1 and 1 < high < 6
    rows = robustness.paired_changes([nominal, worse, swapped])
    assert [(r["value"], r["told_apart"]) for r in rows] == [(1.3, True), (0.7, False)]
    table = robustness.changes_table([nominal, worse, swapped])
    assert "mass x 1.3 | -8 (" in table and "| yes |" in table and "| no |" in table


def test_a_paired_difference_refuses_records_it_cannot_pair():
    nominal = _paired_record("nominal", 1.0, [1, 0, 1], [0, 1, 2])
    with pytest.raises(ValueError, match="same goals"):
        robustness.paired_difference(_paired_record("mass", 1.3, [1, 1, 1], [0, 1, 3]), nominal)
    old = dict(_paired_record("mass", 1.3, [1, 1, 1], [0, 1, 2]), records={})
    with pytest.raises(ValueError, match="no episodes kept"):
        robustness.paired_difference(old, nominal)


@pytest.mark.slow
@pytest.mark.mpi
def test_the_benchmark_under_mpiexec_writes_every_file_and_resumes(tmp_path):
    """The command of benchmarks/results/robustness/README.md, at 2 episodes per setting:
    under two ranks only rank 0 reports (rank 1 once crashed on the record it does not get)."""
    import sys
    from pathlib import Path

    from test_mpi import run_mpi

    script = Path(__file__).parents[1] / "benchmarks" / "robustness.py"
    args = [sys.executable, str(script), "--episodes", "2", "--parameters", "mass",
            "--factors", "1.3", "--noise", "0", "--out", str(tmp_path)]
    first = run_mpi(2, *args, timeout=300)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "nodes4_mass_1.3.json", "nodes4_nominal.json", "results.md", "robustness.png"]
    table = (tmp_path / "results.md").read_text()
    assert "mass x 1.3 | 2 |" in table and "paired 95% CI" in table
    assert first.stdout.count("nodes4_mass_1.3.json: done") == 1  # rank 0 only
    again = run_mpi(2, *args)
    assert "0 s now" in again.stdout  # read back, not replayed


# The options of lesson 16's prediction (its answer cell's "choices"), by perturbed parameter.
PREDICTION_OPTIONS = {"youngs_modulus": "a", "mass": "b", "damping": "c", robustness.NOISE: "d"}


def test_lesson_16s_answer_is_the_committed_benchmarks():
    """The instructor's note of lesson 16 names the option that the committed results
    (benchmarks/results/robustness/) give: the change whose paired interval at 0.05 m lies
    wholly below the training world, by the largest drop, or (e) when none does; and the
    results are of the agent the lesson evaluates, today's data/checkpoints/nodes4."""
    import re

    from dlo_course.grading.notebooks import SOLUTIONS_DIR, read_notebook
    from dlo_course.paths import AGENTS_DIR, REPO_ROOT
    from dlo_course.reproduce import actor_digest

    results = robustness.load_results(REPO_ROOT / "benchmarks" / "results" / "robustness")
    assert results and {r["controller"] for r in results} == {"nodes4"}
    assert {r["episodes"] for r in results} == {100}
    rows = robustness.paired_changes(results)
    drops = [r for r in rows if r["told_apart"] and r["difference"] < 0]
    expected = PREDICTION_OPTIONS[min(drops, key=lambda r: r["difference"])["parameter"]] \
        if drops else "e"
    nb = read_notebook(SOLUTIONS_DIR / "16_robustness.ipynb")
    answer = next(c for c in nb["cells"]
                  if c["metadata"].get("dlo_course", {}).get("answer") == "prediction_robustness")
    assert len(answer["metadata"]["dlo_course"]["choices"]) == len(PREDICTION_OPTIONS) + 1
    note = next(c for c in nb["cells"]
                if "answer: prediction_robustness" in "".join(c["source"]))
    assert re.findall(r"option\s+\(([a-e])\)", "".join(note["source"])) == [expected]
    readme = (REPO_ROOT / "benchmarks" / "results" / "robustness" / "README.md").read_text()
    assert actor_digest(AGENTS_DIR / "nodes4") in readme  # the agent the results were made of
