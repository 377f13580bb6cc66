import csv
import dataclasses
import json

import gymnasium
import numpy as np
import pytest
import torch
from click.testing import CliRunner

from dlo_course.cli import main, train as train_command
from dlo_course.config import PRESETS, DDPGConfig, TrainConfig, preset
from dlo_course.ddpg import DDPG, load_network
from dlo_course.noise import OUNoise
from dlo_course.replay_buffer import ReplayBuffer
from dlo_course.rundir import (PROGRESS_COLUMNS, load_config, read_progress, ship_run,
                              validated_actors)
from dlo_course.trainer import make_env, run_episode, train, validation_indices


# --- tiny test environments ---

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


class ReachShape(gymnasium.Env):
    """A pure-NumPy stand-in for DLOShape-v0, for hindsight relabelling: its layout
    [tip 3 | tip velocity 3 | P_c 3m | P_d 3m], its reward -mean ||P_c - P_d||, terminated
    below ``threshold``. Two "nodes" hang rigidly below the tip, which an action moves by up
    to 6 cm; the goal is that shape shifted by up to 30 cm."""

    n_nodes, threshold = 2, 0.01
    observation_space = gymnasium.spaces.Box(-10.0, 10.0, (6 + 6 * 2,), np.float32)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (3,), np.float32)
    below_tip = np.array([[0.0, 0.0, -0.3], [0.0, 0.0, -0.6]])

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.tip, self.velocity = np.zeros(3), np.zeros(3)
        self.goal = self.below_tip + self.np_random.uniform(-0.3, 0.3, 3)
        return self._observe()

    def step(self, action):
        self.velocity = 0.06 * np.clip(action, -1.0, 1.0)
        self.tip = self.tip + self.velocity
        obs, info = self._observe()
        return obs, -info["distance"], info["is_success"], False, info

    def _observe(self):
        nodes = self.tip + self.below_tip
        distance = float(np.mean(np.linalg.norm(nodes - self.goal, axis=1)))
        obs = np.concatenate([self.tip, self.velocity, nodes.ravel(), self.goal.ravel()])
        return obs.astype(np.float32), {"distance": distance,
                                        "is_success": distance < self.threshold}


class Crashing(gymnasium.Wrapper):
    """Raises at the ``crash_at``-th step made by any instance (a killed run)."""

    crash_at: int | None = None
    steps = 0

    def step(self, action):
        Crashing.steps += 1
        if Crashing.crash_at is not None and Crashing.steps >= self.crash_at:
            raise RuntimeError("simulated crash")
        return super().step(action)


gymnasium.register("test/ReachAtStep3-v0", entry_point=ReachAtStep3)
gymnasium.register("test/ReachShape-v0", entry_point=ReachShape)
gymnasium.register("test/CrashingPendulum-v0",
                   entry_point=lambda **kw: Crashing(gymnasium.make("Pendulum-v1", **kw)))
gymnasium.register("test/CrashingReachShape-v0",
                   entry_point=lambda **kw: Crashing(gymnasium.make("test/ReachShape-v0", **kw)))

# Every lever of issue 12 at once, on small networks: for the goal environment above.
# (With these sizes the checkpoint of episode 2 falls after 62 updates, not a multiple of
# policy_delay: a resume that lost the update count would update the actor off beat.)
LEVERS = dict(her_k=2, updates_per_step=2,
              ddpg=DDPGConfig(hidden_sizes=(32, 32), batch_size=20, buffer_size=800,
                              twin_critics=True, policy_delay=3, target_noise=0.2,
                              target_noise_clip=0.3))


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
    config = tiny(tmp_path, env_id="test/ReachAtStep3-v0", episodes=2, steps_per_episode=10,
                  stop_at_goal=True)
    env = make_env(config)
    agent = DDPG(2, 3, -1.0, 1.0, config.ddpg)
    buffer = ReplayBuffer(2, 3, 100, seed=0)
    stats = run_episode(env, agent, buffer, OUNoise(3, seed=0), config, 0, None)
    assert (stats["length"], stats["distance"], stats["success"]) == (3, pytest.approx(0.1 / 3), 1)
    np.testing.assert_array_equal(buffer.done[:3], [0, 0, 1])

    # The paper's episodes run on past the goal: all 10 steps, done = 1 only where reached,
    # and the episode counts as a success because the goal was reached on the way.
    config = dataclasses.replace(config, stop_at_goal=False)
    buffer = ReplayBuffer(2, 3, 100, seed=0)
    stats = run_episode(env, agent, buffer, OUNoise(3, seed=0), config, 0, None)
    assert (stats["length"], stats["distance"], stats["success"]) == (10, pytest.approx(0.01), 1)
    np.testing.assert_array_equal(buffer.done[:10], [0, 0, 1, 0, 0, 0, 0, 0, 0, 0])

    # a time limit (truncation) is not a terminal state
    config = tiny(tmp_path, steps_per_episode=5)
    env = make_env(config)
    buffer = ReplayBuffer(3, 1, 100, seed=0)
    stats = run_episode(env, DDPG(3, 1, -2.0, 2.0, config.ddpg), buffer, OUNoise(1, seed=0),
                        config, 0, None)
    assert stats["length"] == 5 and len(buffer) == 5 and not buffer.done[:5].any()

    out = train(tiny(tmp_path, "reach", env_id="test/ReachAtStep3-v0", episodes=2,
                     stop_at_goal=True), progress=False)
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


@pytest.mark.parametrize("levers", [False, True], ids=["paper", "her_td3"])
def test_killed_run_resumes_from_its_last_checkpoint(tmp_path, levers):
    # With the levers: hindsight copies (their generator is checkpointed), twin critics (the
    # second one and its optimiser are), a policy delay (the update count is) and target
    # noise (torch's generator is).
    env_id = "test/CrashingReachShape-v0" if levers else "test/CrashingPendulum-v0"

    def config(name):
        return tiny(tmp_path, name, env_id=env_id, episodes=5, **(LEVERS if levers else {}))

    Crashing.crash_at = None
    whole = train(config("whole"), progress=False)

    Crashing.steps, Crashing.crash_at = 0, 3 * 25 + 10  # during episode 4
    with pytest.raises(RuntimeError, match="simulated crash"):
        train(config("killed"), progress=False)
    killed = tmp_path / "killed"
    assert len(read_rows(killed)) == 3  # episode 3 was logged after the checkpoint of episode 2
    assert json.loads((killed / "checkpoints" / "latest.json").read_text())["episodes_done"] == 2

    Crashing.crash_at = None
    train(config("killed"), resume=True, progress=False)
    assert read_rows(killed) == read_rows(whole)
    assert same_weights(killed, whole)
    if levers:
        assert int(read_rows(whole)[-1]["updates"]) > 0
        shared = torch.load(killed / "checkpoints" / "episode000005" / "shared.pt",
                            weights_only=False)
        whole_shared = torch.load(whole / "checkpoints" / "episode000005" / "shared.pt",
                                  weights_only=False)
        for name in ("critic2", "critic2_target"):
            assert all(torch.equal(shared["agent"][name][k], whole_shared["agent"][name][k])
                       for k in shared["agent"][name])


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


# --- the training levers of issue 12 (all off by default and in the paper preset) ---

LEVER_DEFAULTS = {"her_k": 0, "reset_between_episodes": True, "updates_per_step": 1,
                  "stop_at_goal": False}
TD3_DEFAULTS = {"twin_critics": False, "policy_delay": 1, "target_noise": 0.0}


def levers_of(config):
    return ({k: getattr(config, k) for k in LEVER_DEFAULTS},
            {k: getattr(config.ddpg, k) for k in TD3_DEFAULTS})


def test_levers_are_off_by_default_and_in_the_paper_preset():
    assert levers_of(TrainConfig()) == levers_of(PRESETS["paper"]) == (LEVER_DEFAULTS,
                                                                       TD3_DEFAULTS)
    assert PRESETS["paper"].ddpg == DDPGConfig()
    for name in ("smoke", "laptop", "course"):  # the older presets do not use the new levers
        lever, td3 = levers_of(PRESETS[name])
        assert td3 == TD3_DEFAULTS and lever["her_k"] == 0 and lever["reset_between_episodes"]
    with pytest.raises(ValueError, match="her_k"):
        TrainConfig(her_k=-1)


def test_recipe_preset():
    recipe = preset("recipe")
    assert recipe.env_id == "DLOShape-v0" and recipe.env_kwargs == {"n_nodes": 4,
                                                                    "threshold": 0.03}
    assert (recipe.episodes, recipe.steps_per_episode, recipe.checkpoint_every,
            recipe.expected_agents, recipe.updates_per_step, recipe.her_k,
            recipe.reset_between_episodes, recipe.reduce, recipe.stop_at_goal) == \
        (500, 60, 10, 2, 2, 4, False, "sum", False)
    assert (recipe.validate_every, recipe.validation_goals, recipe.validation_steps) == (20, 30, 30)
    assert PRESETS["paper"].validate_every == 0  # the paper kept its last actor
    d = recipe.ddpg
    assert (d.normalize_obs, d.preactivation_l2, d.noise_sigma, d.batch_size, d.buffer_size,
            d.twin_critics, d.policy_delay, d.target_noise, d.target_noise_clip) == \
        (True, 0.01, 0.15, 256, 200_000, True, 2, 0.1, 0.3)
    # Everything else is the paper's DDPG.
    import dataclasses
    assert dataclasses.replace(d, **{k: getattr(DDPGConfig(), k) for k in (
        "normalize_obs", "preactivation_l2", "noise_sigma", "batch_size", "buffer_size",
        "twin_critics", "policy_delay", "target_noise", "target_noise_clip")}) == DDPGConfig()


def test_hindsight_copies_follow_each_episode(tmp_path):
    config = tiny(tmp_path, env_id="test/ReachShape-v0", steps_per_episode=10, her_k=3,
                  warmup=10**9)
    env = make_env(config)
    buffer = ReplayBuffer(18, 3, 500, seed=0)
    with pytest.raises(ValueError, match="HindsightRelabeller"):
        run_episode(env, DDPG(18, 3, config=config.ddpg), buffer, OUNoise(3, seed=0), config,
                    0, None)
    from dlo_course.her import HindsightRelabeller
    her = HindsightRelabeller.for_env(env, k=3, seed=0)
    agent = DDPG(18, 3, config=config.ddpg)
    stats = run_episode(env, agent, buffer, OUNoise(3, seed=0), config, 0, None, her)
    T = 10
    assert stats["length"] == T and len(buffer) == T * (1 + 3)
    real_obs, real_next = buffer.obs[:T], buffer.next_obs[:T]
    for i in range(T, T * 4):  # the copies, after the episode's real transitions
        (t,) = np.flatnonzero((real_obs[:, :12] == buffer.obs[i, :12]).all(axis=1))
        np.testing.assert_array_equal(buffer.act[i], buffer.act[t])
        np.testing.assert_array_equal(buffer.next_obs[i, :12], real_next[t, :12])
        goal = buffer.obs[i, 12:]
        np.testing.assert_array_equal(buffer.next_obs[i, 12:], goal)
        reached_at = [u for u in range(T) if np.array_equal(real_next[u, 6:12], goal)]
        assert reached_at and max(reached_at) >= t  # a shape reached at or after step t
        distance = np.mean(np.linalg.norm((real_next[t, 6:12] - goal).reshape(2, 3), axis=1))
        assert buffer.rew[i] == pytest.approx(-distance, abs=1e-6)
        assert buffer.done[i] == float(distance < ReachShape.threshold)
    assert buffer.done[T * 4 - 3:T * 4].all()  # the last step can only be relabelled with t' = t


def test_levers_need_the_right_environment(tmp_path):
    with pytest.raises(ValueError, match="needs a goal-reaching environment"):
        train(tiny(tmp_path, "her", her_k=4), progress=False)
    with pytest.raises(ValueError, match="needs DLOShape-v0"):
        train(tiny(tmp_path, "keep", reset_between_episodes=False), progress=False)
    assert not (tmp_path / "her").exists() and not (tmp_path / "keep").exists()


def test_levers_are_recorded_and_set_from_the_command_line(tmp_path):
    out = tmp_path / "cli"
    result = CliRunner().invoke(main, [
        "train", "--preset", "smoke", "--env", "test/ReachShape-v0", "--episodes", "2",
        "--steps-per-episode", "12", "--her-k", "3", "--twin-critics", "--policy-delay", "3",
        "--target-noise", "0.2", "--target-noise-clip", "0.4", "--batch-size", "20",
        "--updates-per-step", "2", "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    recorded = json.loads((out / "config.json").read_text())["config"]
    assert (recorded["her_k"], recorded["updates_per_step"],
            recorded["reset_between_episodes"]) == (3, 2, True)
    assert {k: recorded["ddpg"][k] for k in ("twin_critics", "policy_delay", "target_noise",
                                             "target_noise_clip", "batch_size")} == \
        {"twin_critics": True, "policy_delay": 3, "target_noise": 0.2,
         "target_noise_clip": 0.4, "batch_size": 20}
    config = load_config(out)
    assert config.her_k == 3 and config.ddpg.twin_critics and config.ddpg.policy_delay == 3
    rows = read_rows(out)
    assert int(rows[-1]["updates"]) > 0 and rows[-1]["policy_loss"] != ""
    # The exported critic is the first one.
    agent = torch.load(out / "checkpoints" / "episode000002" / "shared.pt",
                       weights_only=False)["agent"]
    critic = load_network(out / "critic.pt").state_dict()
    assert all(torch.equal(critic[k], agent["critic"][k]) for k in critic)
    assert not all(torch.equal(critic[k], agent["critic2"][k]) for k in critic)

    # A run checkpointed before the levers existed resumes, its missing options read as off.
    train(tiny(tmp_path, "old", episodes=1), progress=False)
    shared_old = tmp_path / "old" / "checkpoints" / "episode000001" / "shared.pt"
    blob = torch.load(shared_old, weights_only=False)
    for key in ("her_k", "reset_between_episodes", "stop_at_goal"):
        del blob["config"][key]
    for key in ("twin_critics", "policy_delay", "target_noise", "target_noise_clip"):
        del blob["config"]["ddpg"][key]
    del blob["agent"]["updates"]
    torch.save(blob, shared_old)
    # Its episodes stopped at the goal (no stop_at_goal then): resuming them to run on past
    # the goal would change the run, so only the old behaviour resumes.
    with pytest.raises(ValueError, match="stop_at_goal"):
        train(tiny(tmp_path, "old", episodes=2), resume=True, progress=False)
    train(tiny(tmp_path, "old", episodes=2, stop_at_goal=True), resume=True, progress=False)
    assert len(read_rows(tmp_path / "old")) == 2
    # A config.json from before stop_at_goal reads as its trainer behaved: episodes stopped.
    saved = json.loads((tmp_path / "old" / "config.json").read_text())
    del saved["config"]["stop_at_goal"]
    (tmp_path / "old" / "config.json").write_text(json.dumps(saved))
    assert load_config(tmp_path / "old").stop_at_goal is True
    assert TrainConfig.from_dict({}).stop_at_goal is True and TrainConfig().stop_at_goal is False

    # The preset's value is the default; a lever on the wrong environment is a clear error.
    result = CliRunner().invoke(main, ["train", "--env", "Pendulum-v1", "--keep-shape",
                                       "--out", str(tmp_path / "keep"), "--no-progress"])
    assert result.exit_code == 1 and "needs DLOShape-v0" in result.output


@pytest.mark.slow
def test_keep_shape_between_episodes_on_the_rod(tmp_path):
    """reset_between_episodes=False: episode 2 starts from the shape episode 1 ended in;
    True: from the initial shape. Runs the real simulator: 2 x 2 episodes of 3 actions."""
    from types import SimpleNamespace

    from dlo_course.env import DLOShapeEnv

    goals = np.array([[[1.0, 0.3, 0.7], [1.0, 0.3, 1.2]]])  # far: no episode terminates
    push = np.array([-1.0, 1.0, -1.0], np.float32)
    agent = SimpleNamespace(act=lambda obs, noise: push)  # the same action at every step
    noise = SimpleNamespace(reset=lambda: None)

    def two_episodes(keep_shape):
        config = TrainConfig(env_kwargs={"n_nodes": 2, "goals": goals}, steps_per_episode=3,
                             warmup=10**9, reset_between_episodes=not keep_shape)
        env = make_env(config)
        starts = []
        try:
            buffer = ReplayBuffer(18, 3, 10, seed=0)
            for episode in range(2):
                run_episode(env, agent, buffer, noise, config, seed=episode, grad_reducer=None)
                starts.append(buffer.obs[3 * episode].copy())
            end_of_first = buffer.next_obs[2].copy()
        finally:
            env.close()
        return starts, end_of_first

    starts, end_of_first = two_episodes(keep_shape=True)
    # What the environment's own reset that keeps the shape gives after the same 3 actions
    # (it may let the rod settle a few physics steps before observing, as the authors' did).
    reference = DLOShapeEnv(n_nodes=2, goals=goals)
    try:
        reference.reset(seed=0)
        for _ in range(3):
            reference.step(push)
        kept, _ = reference.reset(seed=1, options={"reinitialize": False})
    finally:
        reference.close()
    np.testing.assert_array_equal(starts[1], kept)
    shape = slice(6, 12)  # P_c
    moved = np.abs(end_of_first[shape] - starts[0][shape]).max()
    assert moved > 0.05  # the 3 actions really deformed the rod...
    assert np.abs(starts[1][shape] - starts[0][shape]).max() > moved / 2  # ...and it stays so

    starts_rebuilt, _ = two_episodes(keep_shape=False)
    np.testing.assert_array_equal(starts_rebuilt[1][shape], starts_rebuilt[0][shape])
    np.testing.assert_array_equal(starts_rebuilt[0], starts[0])


@pytest.mark.slow
def test_recipe_smoke_run_on_the_rod(tmp_path):
    """The recipe's levers together, on the real rod, in one process: 2 episodes of 6
    actions (a batch of 16 so that updates start), then a resume for one more episode."""
    config = preset("recipe", episodes=2, steps_per_episode=6, out_dir=str(tmp_path / "run"),
                    checkpoint_every=1, expected_agents=None, validate_every=2,
                    validation_goals=2, validation_steps=3)
    config.ddpg.batch_size = 16
    run = tmp_path / "run"
    train(config, progress=False)
    progress = read_progress(run)
    assert list(progress["episode"]) == [1, 2]
    assert progress["updates"][-1] > 0  # HER copies filled a batch within the first episode
    saved = json.loads((run / "config.json").read_text())["config"]
    assert saved["her_k"] == 4 and saved["reset_between_episodes"] is False
    assert saved["ddpg"]["twin_critics"] is True
    # One validation, after episode 2; the first one is always the best so far.
    with open(run / "validation.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["episode"], r["best"]) for r in rows] == [("2", "1")]
    best = json.loads((run / "best.json").read_text())
    assert best["episode"] == 2 and best["done_rate"] == float(rows[0]["done_rate"])
    assert 0 < best["distance_mean"] < 1
    config.episodes = 3
    train(config, resume=True, progress=False)
    assert list(read_progress(run)["episode"]) == [1, 2, 3]
    with open(run / "validation.csv", newline="") as f:
        assert [r["episode"] for r in csv.DictReader(f)] == ["2"]  # kept across the resume
    shipped = ship_run(run, tmp_path / "shipped", actor="best")
    record = json.loads((shipped / "record.json").read_text())
    assert record["selected"]["episode"] == 2 and record["episodes_per_agent"] == 3
    assert (shipped / "actor.pt").read_bytes() == (run / "best_actor.pt").read_bytes()
    # Every validated actor is kept, in the run and in the shipped agent, for a later choice.
    kept = validated_actors(run)
    assert list(kept) == [2] and list(validated_actors(shipped)) == [2]
    best_weights = load_network(run / "best_actor.pt").state_dict()
    for name, weights in load_network(kept[2]).state_dict().items():
        assert torch.equal(weights, best_weights[name]), name


def test_validation_goals_hold_out_the_papers_test_goals():
    """Choosing the best actor must not peek at the test: the validation goals are training
    goals that are not among the paper's test goals, drawn from the run's seed."""
    from dlo_course.database import load_database
    from dlo_course.env import DLOShapeEnv

    env = DLOShapeEnv(n_nodes=4)  # not reset: no world is built
    try:
        config = preset("recipe")
        picked = validation_indices(env, config)
        assert len(picked) == 30 == len(np.unique(picked))
        assert not np.isin(picked, load_database("small").test_indices(4)).any()
        np.testing.assert_array_equal(picked, validation_indices(env, config))
        other = validation_indices(env, dataclasses.replace(config, seed=1))
        assert not np.array_equal(picked, other)
        with pytest.raises(ValueError, match="validation_goals"):
            validation_indices(env, dataclasses.replace(config, validation_goals=10_000))
    finally:
        env.close()


# --- the student's episode function (lesson 09) trains the agent ---

def solution_play_episode():
    from dlo_course import pendulum
    from dlo_course.paths import REPO_ROOT

    return pendulum.earlier_answer("09_training_ddpg_on_the_dlo", "play_episode",
                                   REPO_ROOT / "solutions")


def test_the_solutions_play_episode_trains_as_the_library(tmp_path):
    """One agent, episodes that end at the goal, no hindsight copies: the run that lesson
    09's solution plays is the library's, bit for bit; with copies it stores them too."""
    play = solution_play_episode()
    settings = dict(env_id="test/ReachShape-v0", steps_per_episode=10, stop_at_goal=True,
                    updates_per_step=2, ddpg=DDPGConfig(hidden_sizes=(32, 32), batch_size=8,
                                                        buffer_size=500))
    library = train(tiny(tmp_path, "library", **settings), progress=False)
    student = train(tiny(tmp_path, "student", **settings), progress=False, play_episode=play)
    assert read_rows(student) == read_rows(library)
    assert same_weights(student, library)

    relabelled = train(tiny(tmp_path, "her", her_k=2, **settings), progress=False,
                       play_episode=play)
    rows = read_rows(relabelled)
    assert not same_weights(relabelled, library)
    assert all(r["critic_loss"] != "" for r in rows[1:])  # it learned from a full buffer


def test_an_episode_function_needs_one_agent_stopping_at_the_goal(tmp_path):
    play = solution_play_episode()
    with pytest.raises(ValueError, match="stop_at_goal=True"):
        train(tiny(tmp_path, stop_at_goal=False), progress=False, play_episode=play)

    def liar(*args, **kwargs):
        return {**play(*args, **kwargs), "updates": 0}

    with pytest.raises(ValueError, match="it called update"):
        train(tiny(tmp_path, "liar", stop_at_goal=True), progress=False, play_episode=liar)
