"""The Table I protocol: statistics, reinitialisation modes, the MPI split, bad checkpoints."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from dlo_course.ddpg import Actor, Critic, save_network
from dlo_course.env import DLOShapeEnv
from dlo_course.simulation import SimParams
from dlo_course.evaluation import (
    EpisodeRecord, EpisodeTrace, TrainedAgentError, evaluate,
    evaluate_thresholds, goal_schedule, load_actor, run_episodes, run_traces, summarize,
    wilson_interval,
)

MPIEXEC = Path(sys.executable).parent / "mpiexec"


def record(i, done, distance, steps=5):
    return EpisodeRecord(episode=i, goal_index=0, done=done, final_distance=distance,
                         steps=steps, start_distance=0.2)


def test_summary_statistics_on_hand_made_records():
    records = [record(0, True, 0.04), record(1, True, 0.02), record(2, False, 0.09),
               record(3, True, 0.03, steps=11)]
    s = summarize(records)
    assert s.episodes == 4
    assert s.done_percent == 75.0
    assert s.mean_distance == pytest.approx(0.045)
    # population sigma: sqrt(((-.005)^2 + (-.025)^2 + .045^2 + (-.015)^2) / 4)
    assert s.std_distance == pytest.approx(np.sqrt((0.005**2 + 0.025**2 + 0.045**2
                                                    + 0.015**2) / 4))
    assert s.best_distance == 0.02
    assert s.mean_steps == pytest.approx(6.5)
    assert s.done_ci_low < 75.0 < s.done_ci_high
    with pytest.raises(ValueError):
        summarize([])


def test_wilson_interval_known_values():
    # Textbook values of the 95% Wilson score interval.
    assert wilson_interval(8, 10) == pytest.approx((0.4902, 0.9433), abs=1e-4)
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    low, high = wilson_interval(995, 1000)
    assert low == pytest.approx(0.98837, abs=1e-4) and high == pytest.approx(0.99786, abs=1e-4)
    with pytest.raises(ValueError):
        wilson_interval(3, 0)


def test_goal_schedule_is_seeded():
    np.testing.assert_array_equal(goal_schedule(930, 50, 7), goal_schedule(930, 50, 7))
    assert not np.array_equal(goal_schedule(930, 50, 7), goal_schedule(930, 50, 8))


@pytest.fixture
def checkpoint(tmp_path):
    torch.manual_seed(0)
    path = tmp_path / "run"
    path.mkdir()
    save_network(Actor(obs_dim=18, act_dim=3, hidden_sizes=(32, 32)), path / "actor.pt")
    return path


@pytest.fixture
def goals_2():
    # Goals a few cm beside the straight rod: some episodes finish, some do not.
    return np.array([[[1.22, 0.0, 1.26], [1.22, 0.0, 0.73]],
                     [[1.25, 0.05, 1.24], [1.24, 0.04, 0.72]],
                     [[1.10, 0.20, 1.10], [1.15, 0.15, 0.60]]])


def test_bad_trained_agents_give_clear_errors(tmp_path, checkpoint):
    with pytest.raises(TrainedAgentError, match="no trained agent"):
        load_actor(tmp_path / "nowhere")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "actor.pt").write_bytes(b"\x00garbage")
    with pytest.raises(TrainedAgentError, match="not a readable"):
        load_actor(corrupt)
    critic = tmp_path / "critic"
    critic.mkdir()
    save_network(Critic(obs_dim=18, act_dim=3), critic / "actor.pt")
    with pytest.raises(TrainedAgentError, match="not an Actor"):
        load_actor(critic)
    pendulum = tmp_path / "pendulum"
    pendulum.mkdir()
    save_network(Actor(obs_dim=3, act_dim=1), pendulum / "actor.pt")
    with pytest.raises(TrainedAgentError, match="not trained on DLOShape"):
        load_actor(pendulum)
    with pytest.raises(TrainedAgentError, match="trained for 2 nodes"):
        load_actor(checkpoint, n_nodes=6)
    actor, n_nodes = load_actor(checkpoint)
    assert n_nodes == 2 and not actor.training


@pytest.mark.slow
def test_parallel_split_equals_one_process_with_reinitialization(checkpoint, goals_2):
    actor, _ = load_actor(checkpoint)
    schedule = goal_schedule(len(goals_2), 4, seed=3)
    env = DLOShapeEnv(n_nodes=2, goals=goals_2, threshold=0.05)
    try:
        one = run_episodes(actor, env, [0, 1, 2, 3], schedule, True, max_steps=3)
        rank0 = run_episodes(actor, env, [0, 2], schedule, True, max_steps=3)
        rank1 = run_episodes(actor, env, [1, 3], schedule, True, max_steps=3)
    finally:
        env.close()
    assert sorted(rank0 + rank1, key=lambda r: r.episode) == one
    assert [r.goal_index for r in one] == list(schedule)


def test_one_trace_scores_every_threshold_above_its_own():
    trace = EpisodeTrace(0.2, (0.12, 0.06, 0.045, 0.028, 0.02))
    assert trace.record(3, 7, 0.05) == EpisodeRecord(3, 7, True, 0.045, 3, 0.2)
    assert trace.record(3, 7, 0.03) == EpisodeRecord(3, 7, True, 0.028, 4, 0.2)
    assert trace.record(3, 7, 0.01) == EpisodeRecord(3, 7, False, 0.02, 5, 0.2)
    assert EpisodeTrace(0.2, ()).record(0, 0, 0.05).final_distance == 0.2


@pytest.mark.slow
def test_shared_thresholds_equal_separate_runs(checkpoint, goals_2):
    """With reinitialisation, one run at 0.03 m scores 0.05 m exactly as a run at 0.05 m
    does; episodes with a goal already played are not simulated again."""
    shared = evaluate_thresholds(checkpoint, goals_2, (0.05, 0.03), episodes=5, max_steps=3,
                                 seed=2, show_progress=False)
    for threshold in (0.05, 0.03):
        summary, records = evaluate(checkpoint, goals_2, threshold, episodes=5, max_steps=3,
                                    seed=2, show_progress=False)
        assert shared[threshold][1] == records and shared[threshold][0] == summary
    assert any(r.done for r in shared[0.05][1])  # the test means something at 0.05 m


@pytest.mark.slow
def test_repeated_goals_are_simulated_once_with_reinitialization(checkpoint, goals_2):
    actor, _ = load_actor(checkpoint)
    env = DLOShapeEnv(n_nodes=2, goals=goals_2, threshold=0.05)
    resets = []
    original = env.reset
    env.reset = lambda **kw: (resets.append(kw), original(**kw))[1]
    try:
        records = run_episodes(actor, env, [0, 1, 2], np.array([1, 1, 1]), True, max_steps=2)
    finally:
        env.close()
    assert len(resets) == 1
    assert records[0].done == records[2].done and records[0].final_distance == records[2].final_distance
    assert [r.episode for r in records] == [0, 1, 2]


@pytest.mark.slow
def test_forked_episodes_equal_rebuilt_ones_bit_for_bit(checkpoint, goals_2):
    """With reinitialisation the world is settled once and each episode runs in a forked
    copy of it (dlo_course.snapshot): the same traces as rebuilding before every episode,
    for a trained actor and for a controller with memory; the parent's world is untouched."""
    from dlo_course.jacobian import JacobianController

    actor, _ = load_actor(checkpoint)
    schedule = np.array([2, 0, 1])
    env = DLOShapeEnv(n_nodes=2, goals=goals_2, threshold=0.01)
    try:
        controller = JacobianController(n_nodes=2)
        controller.bind(env)
        for policy in (actor, controller):
            forked = run_traces(policy, env, [0, 1, 2], schedule, True, 4, fork=True)
            before = env.scene.node_positions()
            rebuilt = run_traces(policy, env, [0, 1, 2], schedule, True, 4, fork=False)
            assert forked == rebuilt
            assert len({t.distances for t in forked}) == 3  # three different episodes
        # after forked episodes the parent still holds the settled world, not an episode's end
        run_traces(actor, env, [0], schedule, True, 4, fork=True)
        np.testing.assert_array_equal(env.scene.node_positions(), before)
    finally:
        env.close()


def test_without_reinitialization_episodes_continue_from_the_last_shape(checkpoint, goals_2):
    actor, _ = load_actor(checkpoint)
    schedule = np.array([2, 2])
    # No settling at reset, so a chained episode starts exactly where the last one ended.
    env = DLOShapeEnv(n_nodes=2, goals=goals_2, threshold=0.001,
                      params=SimParams(reset_settle_steps=0, rebuild_settle_steps=0))
    try:
        chained = run_episodes(actor, env, [0, 1], schedule, False, max_steps=3)
        fresh = run_episodes(actor, env, [0, 1], schedule, True, max_steps=3)
    finally:
        env.close()
    # Same goal twice: without reinitialisation the second episode starts where the first
    # ended; with it, from the initial shape again.
    assert chained[1].start_distance == pytest.approx(chained[0].final_distance)
    assert fresh[1].start_distance == pytest.approx(fresh[0].start_distance)
    assert chained[1].start_distance != pytest.approx(fresh[1].start_distance)


@pytest.mark.mpi
def test_evaluate_under_mpiexec_matches_one_process(tmp_path, checkpoint, goals_2):
    goal_file = tmp_path / "goals.npy"
    np.save(goal_file, goals_2)
    summary, records = evaluate(checkpoint, goals=goal_file, episodes=4, max_steps=3, seed=1,
                                show_progress=False)
    out = tmp_path / "mpi.json"
    cmd = [str(MPIEXEC), "-n", "2", sys.executable, "-m", "dlo_course.cli", "evaluate",
           "--checkpoint", str(checkpoint), "--database", str(goal_file), "--episodes", "4",
           "--max-steps", "3", "--seed", "1", "--out", str(out)]
    subprocess.run(cmd, check=True, timeout=300, capture_output=True)
    result = json.loads(out.read_text())
    assert result["summary"] == pytest.approx(summary.as_dict())
    assert [EpisodeRecord(**r) for r in result["episodes"]] == records


def test_cli_reports_a_mismatched_checkpoint_without_a_traceback(checkpoint):
    result = subprocess.run([sys.executable, "-m", "dlo_course.cli", "evaluate",
                             "--checkpoint", str(checkpoint), "--nodes", "6",
                             "--episodes", "1"], capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert "trained for 2 nodes" in result.stderr
    assert "Traceback" not in result.stderr


def test_recorded_tip_controller_heads_for_the_recorded_tip():
    import torch

    from dlo_course import load_database
    from dlo_course.evaluation import recorded_tip_controller

    db = load_database("small")
    controller = recorded_tip_controller(db, 2)
    i, j = 17, 400
    obs = np.zeros((2, 18), np.float32)
    obs[0, :3] = db.tip[i] + [0.03, 0.0, -0.12]  # 3 cm and 12 cm from goal i's recorded tip
    obs[0, 6 + 6:] = db.goals(2)[i].ravel()
    obs[1, :3] = db.tip[j]
    obs[1, 6 + 6:] = db.goals(2)[j].ravel()
    actions = controller(torch.as_tensor(obs)).numpy()
    np.testing.assert_allclose(actions[0], [-0.5, 0.0, 1.0], atol=1e-4)  # +z clipped to 1
    np.testing.assert_allclose(actions[1], 0.0, atol=1e-5)


@pytest.mark.parametrize("n_nodes", [2, 4, 6])
def test_shipped_agents_load_with_their_training_record(n_nodes):
    import json

    from dlo_course.paths import AGENTS_DIR

    folder = AGENTS_DIR / f"nodes{n_nodes}"
    actor, nodes = load_actor(folder)
    assert nodes == n_nodes and actor.init_kwargs["obs_dim"] == 6 + 6 * n_nodes
    record = json.loads((folder / "record.json").read_text())
    for key in ("ranks", "episodes_per_agent", "transitions", "wall_time_h", "seed", "commit"):
        assert record[key] is not None, key
    other = 4 if n_nodes != 4 else 6
    with pytest.raises(TrainedAgentError, match=f"trained for {n_nodes} nodes"):
        load_actor(folder, other)


def test_cli_scores_several_thresholds(tmp_path, checkpoint, goals_2):
    from click.testing import CliRunner

    from dlo_course.cli import main

    goal_file = tmp_path / "goals.npy"
    np.save(goal_file, goals_2)
    out = tmp_path / "two.json"
    result = CliRunner().invoke(main, [
        "evaluate", "--checkpoint", str(checkpoint), "--database", str(goal_file),
        "--threshold", "0.05", "--threshold", "0.03", "--episodes", "3", "--max-steps", "2",
        "--out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert [d["threshold"] for d in data] == [0.05, 0.03]
    assert all(d["summary"]["episodes"] == 3 for d in data)


def test_seed_interval_matches_the_t_formula():
    from dlo_course.evaluation import seed_interval

    # Three seeds: mean 90, sample std 10, t(2) = 4.303: half-width 4.303 * 10 / sqrt(3).
    mean, low, high = seed_interval([80.0, 90.0, 100.0])
    assert mean == pytest.approx(90.0)
    assert high - mean == pytest.approx(4.303 * 10.0 / np.sqrt(3.0))
    assert mean - low == pytest.approx(high - mean)
    # Per point of a curve: the axis of seeds is reduced, the points are kept.
    curves = np.array([[0.0, 1.0], [2.0, 1.0]])
    m, lo, hi = seed_interval(curves, axis=0)
    assert m.tolist() == [1.0, 1.0] and lo[1] == hi[1] == 1.0 and lo[0] < 0 < 2 < hi[0]
    with pytest.raises(ValueError, match="2 to"):
        seed_interval([1.0])


def test_rank_correlation_is_spearmans():
    from dlo_course.evaluation import rank_correlation

    assert rank_correlation([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1)
    assert rank_correlation([1, 2, 3, 4], [9, 7, 5, 1]) == pytest.approx(-1)
    # Ranks, not values: a monotone transform changes nothing.
    assert rank_correlation([1, 2, 3, 4], [1, 8, 27, 1000]) == pytest.approx(1)
    # Ties take their mean rank: ranks (1.5, 1.5, 3, 4) against (1, 2, 3, 4).
    expected = np.corrcoef([1.5, 1.5, 3, 4], [1, 2, 3, 4])[0, 1]
    assert rank_correlation([5, 5, 6, 7], [1, 2, 3, 4]) == pytest.approx(expected)
    assert np.isnan(rank_correlation([1, 1, 1], [1, 2, 3]))
    with pytest.raises(ValueError):
        rank_correlation([1, 2], [1, 2, 3])


def test_held_out_goals_like_the_test_follow_its_sweep_levels():
    from dlo_course.database import BOXES, load_database, sweep_levels

    database = load_database("small")
    levels = sweep_levels(BOXES["small"])
    test = database.test_indices(4)
    drawn = database.held_out_indices(4, size=2000, seed=7)
    assert not np.isin(drawn, test).any()  # never a test goal
    share = np.bincount(levels[drawn], minlength=6) / len(drawn)
    np.testing.assert_allclose(share, np.bincount(levels[test], minlength=6) / len(test),
                               atol=0.03)  # 735, 158, 37 of 930 on levels 0, 1, 2
    np.testing.assert_array_equal(drawn, database.held_out_indices(4, size=2000, seed=7))
    uniform = database.held_out_indices(4, size=2000, seed=7, like_test=False)
    assert not np.isin(uniform, test).any()
    assert (levels[uniform] >= 3).mean() > 0.5  # most held-out records lie on levels 3-5
