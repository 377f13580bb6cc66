"""Stable-Baselines3 on the rod (dlo_course/baselines.py): it trains on DLOShape-v0 as it is,
resumes, and the course's evaluation plays it as it plays a trained DDPG agent; Gymnasium's
async vector environment runs copies of the rod in their own processes."""

import json
import tempfile

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from dlo_course import baselines  # noqa: E402
from dlo_course.evaluation import evaluate_thresholds, load_actor  # noqa: E402
from dlo_course.reproduce import actor_digest  # noqa: E402

pytestmark = pytest.mark.slow
SMALL = {"batch_size": 8, "learning_starts": 10}  # so that a few steps do update


@pytest.mark.parametrize("algorithm", baselines.ALGORITHMS)
def test_sb3_trains_resumes_and_is_evaluated_by_the_course(algorithm, tmp_path, monkeypatch):
    out = tmp_path / algorithm
    env_kwargs = {"n_nodes": 2, "threshold": 0.05}
    # A temporary folder of this test's own, so that only this run's litter could show.
    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    baselines.train_sb3(algorithm, out, total_steps=14, env_kwargs=env_kwargs,
                        max_episode_steps=8, checkpoint_every=7, progress=False,
                        overrides=SMALL)
    assert not list(temp.glob("SB3-*"))  # SB3's default logger leaves one per learn() call
    state = json.loads((out / baselines.SB3_STATE_FILE).read_text())
    assert state["steps"] == 14 and state["algorithm"] == algorithm
    assert not (out / baselines.SB3_BUFFER_FILE).exists()  # kept only while unfinished
    first = (out / baselines.SB3_MODEL_FILE).read_bytes()
    # A longer run in the same folder continues from step 14 instead of starting over, and
    # says that the finished run's replay buffer is gone.
    with pytest.warns(UserWarning, match="empty buffer of 14 transitions"):
        baselines.train_sb3(algorithm, out, total_steps=20, env_kwargs=env_kwargs,
                            max_episode_steps=8, checkpoint_every=7, progress=False,
                            overrides=SMALL)
    assert json.loads((out / baselines.SB3_STATE_FILE).read_text())["steps"] == 20
    assert (out / baselines.SB3_MODEL_FILE).read_bytes() != first  # it learned on
    with pytest.raises(ValueError, match="another run"):
        baselines.train_sb3(algorithm, out, total_steps=30, env_kwargs=env_kwargs,
                            max_episode_steps=8, seed=1, progress=False, overrides=SMALL)

    actor, n_nodes = load_actor(out)
    assert n_nodes == 2
    obs = np.zeros((4, 18), dtype=np.float32)
    import torch

    actions = actor(torch.as_tensor(obs))
    assert actions.shape == (4, 3) and actions.abs().max() <= 1
    model = baselines.algorithm_class(algorithm).load(out / baselines.SB3_MODEL_FILE)
    np.testing.assert_allclose(actions.numpy(), model.predict(obs, deterministic=True)[0],
                               atol=1e-6)  # SB3's own deterministic action
    assert len(actor_digest(out)) == 12  # cached under its model file, as DDPG's actor
    results = evaluate_thresholds(out, "small-test", [0.05, 0.03], episodes=2, max_steps=3,
                                  n_nodes=2, show_progress=False)
    assert {t: results[t][0].episodes for t in results} == {0.05: 2, 0.03: 2}


def test_a_two_copy_async_vector_env_steps_and_resets():
    """Each copy is its own process with its own PyBullet world."""
    envs = gym.make_vec("DLOShape-v0", num_envs=2, vectorization_mode="async", n_nodes=2,
                        max_episode_steps=3)
    try:
        obs, _ = envs.reset(seed=[0, 1])
        assert obs.shape == (2, 18) and np.isfinite(obs).all()
        for _ in range(4):  # past the time limit: the copies reset themselves
            obs, reward, terminated, truncated, _ = envs.step(np.zeros((2, 3), np.float32))
        assert obs.shape == (2, 18) and reward.shape == (2,)
        assert not np.allclose(obs[0, 6:], obs[1, 6:])  # two goals: two worlds
    finally:
        envs.close()
