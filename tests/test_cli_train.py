"""`dlo-course train`: options generated from the configuration dataclasses, a TOML file of
settings, their precedence (flags over the file over the preset), and clear errors."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from dlo_course import config
from dlo_course.cli import main, train as train_command, train_config
from dlo_course.config import (PRESET_SUMMARIES, DDPGConfig, TrainConfig, config_fields,
                               field_docs, preset)

# A value for every field, none of them the smoke preset's, as config.json holds it.
EVERY_FIELD = {
    "env_id": "Pendulum-v1", "env_kwargs": {"g": 9.5}, "episodes": 3, "steps_per_episode": 7,
    "seed": 5, "out_dir": "OUT", "checkpoint_every": 2, "reduce": "mean", "warmup": 6,
    "expected_agents": 1, "updates_per_step": 2, "her_k": 0, "reset_between_episodes": False,
    "stop_at_goal": True,
    "validate_every": 4, "validation_goals": 3, "validation_steps": 9, "torch_threads": 2,
    "actor_lr": 2e-4, "critic_lr": 3e-3, "batch_size": 8, "buffer_size": 999, "gamma": 0.9,
    "tau": 0.05, "hidden_sizes": [8, 16], "final_init": 0.01, "noise_theta": 0.2,
    "noise_sigma": 0.1, "noise_mu": 0.05, "normalize_obs": True, "preactivation_l2": 0.02,
    "twin_critics": True, "policy_delay": 2, "target_noise": 0.1, "target_noise_clip": 0.3,
}


def flags_for(name: str, value) -> list[str]:
    """The field's generated option set to ``value`` (its --field-name spelling)."""
    option = next(p for p in train_command.params if p.name == name)
    if isinstance(value, bool):
        return [option.opts[0] if value else option.secondary_opts[0]]
    flag = "--" + name.replace("_", "-")
    if isinstance(value, list):
        return [flag, ",".join(map(str, value))]
    return [flag, json.dumps(value) if isinstance(value, dict) else str(value)]


def resolved(*args: str) -> dict:
    """The configuration `dlo-course train ARGS` would run, through --print-config."""
    result = CliRunner().invoke(main, ["train", *args, "--print-config"])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def recorded(settings: dict) -> dict:
    """A field's value wherever it lives in config.json (top level or ddpg)."""
    return {**{k: v for k, v in settings.items() if k != "ddpg"}, **settings["ddpg"]}


def test_every_field_has_an_option_with_its_docstring_as_help():
    options = {p.name: p for p in train_command.params}
    for config_class in (TrainConfig, DDPGConfig):
        docs = field_docs(config_class)
        for f in config_fields(config_class):
            assert f.name in options, f"no option for {config_class.__name__}.{f.name}"
            assert f.name in docs, f"{config_class.__name__}.{f.name} has no docstring"
            first_words = " ".join(docs[f.name].split()[:3]).replace("``", "")
            assert options[f.name].help.startswith(first_words.split(":")[0])
    assert set(EVERY_FIELD) == {f.name for c in (TrainConfig, DDPGConfig)
                                for f in config_fields(c)}


def test_the_flags_that_existed_before_keep_their_names():
    names = {opt for p in train_command.params for opt in p.opts + p.secondary_opts}
    for flag in ["--preset", "--env", "--nodes", "--episodes", "--steps-per-episode", "--seed",
                 "--out", "--resume", "--overwrite", "--reduce", "--checkpoint-every",
                 "--batch-size", "--updates-per-step", "--her-k", "--twin-critics",
                 "--no-twin-critics", "--policy-delay", "--target-noise",
                 "--target-noise-clip", "--reset-between-episodes", "--keep-shape",
                 "--validate-every", "--validation-goals", "--progress", "--no-progress"]:
        assert flag in names, flag


def test_every_option_reaches_the_configuration():
    args = [a for name, value in EVERY_FIELD.items() for a in flags_for(name, value)]
    got = recorded(resolved("--preset", "smoke", *args)["config"])
    for name, value in EVERY_FIELD.items():
        assert got[name] == (pytest.approx(value) if isinstance(value, float) else value), name


def test_without_options_the_configuration_is_the_presets():
    for name in PRESET_SUMMARIES:
        got = resolved("--preset", name)
        expected = preset(name).to_dict()
        nodes = expected["env_kwargs"].get("n_nodes")
        expected["out_dir"] = f"runs/{name}_DLOShape-v0_n{nodes}_seed0"  # as before
        assert got == {"preset": name, "config": json.loads(json.dumps(expected))}
    # an optional field can be set back to None
    assert resolved("--preset", "recipe", "--expected-agents", "none")["config"][
        "expected_agents"] is None


def test_a_run_records_what_the_options_set(tmp_path):
    out = tmp_path / "run"
    args = ["--preset", "smoke", "--env", "Pendulum-v1", "--episodes", "1",
            "--steps-per-episode", "6", "--batch-size", "4", "--warmup", "5",
            "--hidden-sizes", "8,8", "--gamma", "0.95", "--noise-sigma", "0.1",
            "--torch-threads", "1", "--seed", "3", "--out", str(out)]
    expected = resolved(*args)["config"]
    result = CliRunner().invoke(main, ["train", *args, "--no-progress"])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "config.json").read_text())["config"] == expected
    assert expected["ddpg"]["hidden_sizes"] == [8, 8] and expected["warmup"] == 5


def test_a_toml_file_overrides_the_preset_and_the_flags_override_the_file(tmp_path):
    experiment = tmp_path / "experiment.toml"
    experiment.write_text('preset = "recipe"\n'
                          'episodes = 12\nseed = 4\nvalidate_every = 0\n'
                          '[env_kwargs]\ngoals = "large"\n'
                          '[ddpg]\nbatch_size = 64\ntau = 1\nhidden_sizes = [32, 32]\n')
    got = resolved("--config", str(experiment))
    c = got["config"]
    assert got["preset"] == "recipe"
    assert (c["episodes"], c["seed"], c["validate_every"]) == (12, 4, 0)  # the file
    assert c["env_kwargs"] == {"n_nodes": 4, "threshold": 0.03,
                            "goals": "large"}  # merged into the preset's
    assert c["ddpg"]["batch_size"] == 64 and c["ddpg"]["tau"] == 1.0
    assert c["ddpg"]["hidden_sizes"] == [32, 32]
    assert c["her_k"] == 4 and c["ddpg"]["twin_critics"]  # the preset, not in the file
    assert c["out_dir"] == "runs/recipe_DLOShape-v0_n4_seed4"

    got = resolved("--config", str(experiment), "--episodes", "2", "--batch-size", "16",
                   "--nodes", "6", "--preset", "course")
    c = got["config"]
    assert got["preset"] == "course"  # the flag's preset wins over the file's
    assert (c["episodes"], c["seed"]) == (2, 4)
    assert c["ddpg"]["batch_size"] == 16 and c["ddpg"]["tau"] == 1.0
    assert c["env_kwargs"] == {"n_nodes": 6, "goals": "large"}
    assert c["updates_per_step"] == 2 and c["her_k"] == 0  # course preset under the file

    # A file naming out_dir keeps it; another environment drops the preset's arguments.
    experiment.write_text('env_id = "Pendulum-v1"\nout_dir = "runs/mine"\n')
    c = resolved("--config", str(experiment))["config"]
    assert (c["env_id"], c["env_kwargs"], c["out_dir"]) == ("Pendulum-v1", {}, "runs/mine")


def test_the_configuration_can_be_built_without_the_command_line(tmp_path):
    options = {name: None for name in EVERY_FIELD}
    name, built = train_config(None, None, None, {**options, "episodes": 9})
    assert name == "smoke" and built.episodes == 9
    assert built.ddpg == preset("smoke").ddpg


@pytest.mark.parametrize("toml, message", [
    ("episodez = 3\n", "unknown setting 'episodez'; did you mean 'episodes'?"),
    ("[ddpg]\nbatchsize = 3\n", "unknown setting 'ddpg.batchsize'; did you mean "
                                "'ddpg.batch_size'?"),
    ("episodes = 'ten'\n", "episodes must be an integer, got 'ten'"),
    ("episodes = 1.5\n", "episodes must be an integer, got 1.5"),
    ("[ddpg]\ntwin_critics = 1\n", "ddpg.twin_critics must be true or false, got 1"),
    ("[ddpg]\nhidden_sizes = 'wide'\n", "ddpg.hidden_sizes must be a list of integers"),
    ("episodes = 0\n", "episodes must be at least 1, got 0"),
    ("torch_threads = 0\n", "torch_threads must be in [1, inf), got 0"),
    ("reduce = 'max'\n", "reduce must be one of"),
    ("[ddpg]\ntau = 2.0\n", "tau must be in (0, 1], got 2.0"),
    ("ddpg = 3\n", "ddpg must be a table of DDPG settings"),
    ("preset = 'huge'\n", "unknown preset 'huge'"),
    ("episodes = [\n", "is not a valid TOML file"),
])
def test_a_bad_file_is_a_clear_error(tmp_path, toml, message):
    experiment = tmp_path / "bad.toml"
    experiment.write_text(toml)
    result = CliRunner().invoke(main, ["train", "--config", str(experiment), "--print-config"])
    assert result.exit_code == 2, result.output
    assert message in " ".join(result.output.split()), result.output
    assert "Traceback" not in result.output


def test_bad_flags_are_clear_errors(tmp_path):
    runner = CliRunner()
    for args, message in [
            (["--hidden-sizes", "8,x"], "is not a comma-separated list of integers"),
            (["--env-kwargs", "{oops"], "is not JSON"),
            (["--env-kwargs", "[1]"], "is not a JSON object"),
            (["--tau", "0"], "0<x<=1"),
            (["--warmup", "0"], "x>=1"),
            (["--config", str(tmp_path / "missing.toml")], "does not exist"),
            (["--env-kwargs", '{"max_episode_steps": 3}'], "set steps_per_episode")]:
        result = runner.invoke(main, ["train", *args, "--print-config"])
        assert result.exit_code == 2 and message in result.output, (args, result.output)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    result = runner.invoke(main, ["train", "--config", str(binary)])
    assert result.exit_code == 2 and "is not a valid TOML file" in result.output


def test_list_presets_prints_every_preset_and_its_summary():
    result = CliRunner().invoke(main, ["train", "--list-presets"])
    assert result.exit_code == 0
    lines = result.output.splitlines()
    assert len(lines) == len(PRESET_SUMMARIES)
    for line, (name, summary) in zip(lines, PRESET_SUMMARIES.items()):
        assert line.split()[0] == name and line.endswith(summary)


def test_tomllib_missing_is_a_clear_error(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_toml(name, *args, **kwargs):
        if name in ("tomllib", "tomli"):
            raise ModuleNotFoundError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_toml)
    (tmp_path / "x.toml").write_text("episodes = 2\n")
    with pytest.raises(ValueError, match="needs Python 3.11 or later, or the tomli package"):
        config.read_toml(tmp_path / "x.toml")
