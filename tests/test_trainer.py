import csv
import json

import gymnasium
import numpy as np
import pytest
import torch
from click.testing import CliRunner

from dlo_course.cli import main, train as train_command
from dlo_course.ddpg import DDPG, DDPGConfig, load_network
from dlo_course.noise import OUNoise
from dlo_course.replay_buffer import ReplayBuffer
from dlo_course.trainer import (PRESETS, PROGRESS_COLUMNS, TrainConfig, load_config, make_env,
                                preset, run_episode, train)


# --- two tiny test environments ---

class ReachAtStep3(gymnasium.Env):
    """1-D toy: terminates with success at its 3rd step and reports a distance, like the rod."""

    observation_space = gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(2, np.float32), {}

    def step(self, action):
        self.t += 1
        done = self.t == 3
        info = {"distance": 0.1 / self.t, "is_success": done}
        return np.full(2, self.t / 10, np.float32), -0.1 / self.t, done, False, info


class CrashingPendulum(gymnasium.Wrapper):
    """Pendulum that raises at the ``crash_at``-th step made by any instance (a killed run)."""

    crash_at: int | None = None
    steps = 0

    def step(self, action):
        CrashingPendulum.steps += 1
        if CrashingPendulum.crash_at is not None and CrashingPendulum.steps >= self.crash_at:
            raise RuntimeError("simulated crash")
        return super().step(action)


gymnasium.register("test/ReachAtStep3-v0", entry_point=ReachAtStep3)
gymnasium.register("test/CrashingPendulum-v0",
                   entry_point=lambda **kw: CrashingPendulum(gymnasium.make("Pendulum-v1", **kw)))


def tiny(tmp_path, name="run", **overrides) -> TrainConfig:
    settings = dict(env_id="Pendulum-v1", env_kwargs={}, episodes=4, steps_per_episode=25,
                    checkpoint_every=2, out_dir=str(tmp_path / name), seed=3,
                    ddpg=DDPGConfig(hidden_sizes=(32, 32), batch_size=16, buffer_size=500))
    settings.update(overrides)
    return TrainConfig(**settings)


def read_rows(run_dir):
    with (run_dir / "progress.csv").open(newline="") as f:
        return [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(f)]


def same_weights(run_a, run_b) -> bool:
    nets = [(load_network(run_a / f), load_network(run_b / f)) for f in ("actor.pt", "critic.pt")]
    return all(torch.equal(p, q) for a, b in nets for p, q in zip(a.parameters(), b.parameters()))


# --- tests ---

def test_run_writes_its_files(tmp_path):
    config = tiny(tmp_path)
    out = train(config, progress=False)
    rows = read_rows(out)
    assert [int(r["episode"]) for r in rows] == [1, 2, 3, 4]
    assert [int(r["transitions"]) for r in rows] == [25, 50, 75, 100]
    # one update per step once the buffer holds a batch of 16: 10, then 25 per episode
    assert [int(r["updates"]) for r in rows] == [10, 35, 60, 85]
    assert rows[0]["distance_mean"] == "" and rows[0]["success_rate"] == ""  # not reported
    assert list(rows[0]) == [c for c in PROGRESS_COLUMNS if c != "wall_time"]
    actor = load_network(out / "actor.pt")
    assert actor(torch.zeros(1, 3)).abs().max() <= 2.0  # Pendulum's torque bound
    assert load_config(out) == config


def test_done_mask_is_terminated_and_env_info_is_logged(tmp_path):
    config = tiny(tmp_path, env_id="test/ReachAtStep3-v0", episodes=2, steps_per_episode=10)
    env = make_env(config)
    agent = DDPG(2, 3, -1.0, 1.0, config.ddpg)
    buffer = ReplayBuffer(2, 3, 100, seed=0)
    stats = run_episode(env, agent, buffer, OUNoise(3, seed=0), config, 0, None)
    assert (stats["length"], stats["distance"], stats["success"]) == (3, pytest.approx(0.1 / 3), 1)
    np.testing.assert_array_equal(buffer.done[:3], [0, 0, 1])

    # a time limit (truncation) is not a terminal state
    config = tiny(tmp_path, steps_per_episode=5)
    env = make_env(config)
    buffer = ReplayBuffer(3, 1, 100, seed=0)
    stats = run_episode(env, DDPG(3, 1, -2.0, 2.0, config.ddpg), buffer, OUNoise(1, seed=0),
                        config, 0, None)
    assert stats["length"] == 5 and len(buffer) == 5 and not buffer.done[:5].any()

    out = train(tiny(tmp_path, "reach", env_id="test/ReachAtStep3-v0", episodes=2), progress=False)
    rows = read_rows(out)
    assert [r["success_rate"] for r in rows] == ["1", "1"]
    assert float(rows[0]["distance_mean"]) == pytest.approx(0.1 / 3)
    assert [int(r["transitions"]) for r in rows] == [3, 6]


def test_stopped_and_resumed_run_equals_uninterrupted_run(tmp_path):
    whole = train(tiny(tmp_path, "whole"), progress=False)
    part = train(tiny(tmp_path, "part", episodes=2), progress=False)
    assert len(read_rows(part)) == 2
    train(tiny(tmp_path, "part", episodes=4), resume=True, progress=False)
    assert read_rows(part) == read_rows(whole)
    assert same_weights(part, whole)


def test_killed_run_resumes_from_its_last_checkpoint(tmp_path):
    def config(name):
        return tiny(tmp_path, name, env_id="test/CrashingPendulum-v0", episodes=5)

    CrashingPendulum.crash_at = None
    whole = train(config("whole"), progress=False)

    CrashingPendulum.steps, CrashingPendulum.crash_at = 0, 3 * 25 + 10  # during episode 4
    with pytest.raises(RuntimeError, match="simulated crash"):
        train(config("killed"), progress=False)
    killed = tmp_path / "killed"
    assert len(read_rows(killed)) == 3  # episode 3 was logged after the checkpoint of episode 2
    assert json.loads((killed / "checkpoints" / "latest.json").read_text())["episodes_done"] == 2

    CrashingPendulum.crash_at = None
    train(config("killed"), resume=True, progress=False)
    assert read_rows(killed) == read_rows(whole)
    assert same_weights(killed, whole)


def test_bad_input_gives_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown preset 'huge'"):
        preset("huge")
    with pytest.raises(ValueError, match="episodes must be at least 1"):
        TrainConfig(episodes=-3)
    with pytest.raises(ValueError, match="reduce"):
        TrainConfig(reduce="average")
    with pytest.raises(ValueError, match="cannot make environment"):
        train(tiny(tmp_path, env_id="NoSuchEnv-v0"), progress=False)
    with pytest.raises(ValueError, match="1-D Box action space"):
        train(tiny(tmp_path, env_id="CartPole-v1"), progress=False)

    done = train(tiny(tmp_path, "done", episodes=1), progress=False)
    with pytest.raises(FileExistsError, match="--resume"):
        train(tiny(tmp_path, "done", episodes=1), progress=False)
    with pytest.raises(ValueError, match=r"differs in \['seed'\]"):
        train(tiny(tmp_path, "done", episodes=2, seed=4), resume=True, progress=False)
    assert done.exists()

    runner = CliRunner()
    result = runner.invoke(main, ["train", "--episodes", "-3"])
    assert result.exit_code == 2 and "-3 is not in the range x>=1" in result.output
    result = runner.invoke(main, ["train", "--preset", "huge"])
    assert result.exit_code == 2 and "'huge' is not one of" in result.output
    result = runner.invoke(main, ["train", "--env", "Pendulum-v1", "--nodes", "2",
                                  "--out", str(tmp_path / "cli"), "--no-progress"])
    assert result.exit_code == 1 and "cannot make environment" in result.output


def test_presets():
    preset_option = next(p for p in train_command.params if p.name == "preset_name")
    assert sorted(preset_option.type.choices) == sorted(PRESETS)
    paper = preset("paper")
    assert (paper.episodes, paper.steps_per_episode, paper.expected_agents, paper.reduce) == \
        (63, 300, 32, "sum")
    assert paper.ddpg == DDPGConfig()
    smoke = preset("smoke", seed=5)
    assert smoke.seed == 5 and smoke.episodes * smoke.steps_per_episode <= 40
    assert PRESETS["smoke"].seed == 0  # presets are copied, not modified
    # The course preset changes only the documented course options and the budget.
    import dataclasses
    course = preset("course")
    assert dataclasses.replace(course.ddpg, normalize_obs=False, preactivation_l2=0.0,
                               noise_sigma=0.3) == DDPGConfig()
    assert course.updates_per_step == 2 and course.reduce == "sum"


def test_updates_per_step_and_observation_scaling_from_a_bounded_space(tmp_path):
    one = train(tiny(tmp_path, "one", episodes=1), progress=False)
    two = train(tiny(tmp_path, "two", episodes=1, updates_per_step=2,
                     ddpg=DDPGConfig(hidden_sizes=(32, 32), batch_size=16, buffer_size=500,
                                     normalize_obs=True)), progress=False)
    updates = [int(read_rows(run)[-1]["updates"]) for run in (one, two)]
    assert updates[1] == 2 * updates[0] > 0
    # Pendulum's observation box is [-1, 1] x [-1, 1] x [-8, 8]: centre 0, half-widths.
    actor = load_network(two / "actor.pt")
    torch.testing.assert_close(actor.scaling.scale, torch.tensor([1.0, 1.0, 8.0]))
    torch.testing.assert_close(actor.scaling.offset, torch.zeros(3))
    with pytest.raises(ValueError, match="updates_per_step"):
        tiny(tmp_path, updates_per_step=0)
