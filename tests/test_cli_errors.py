"""Truncated or corrupt files given to the command line end in a one-line error that names
the file, never in a traceback from inside numpy, torch or json."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from dlo_course import database
from dlo_course.cli import main
from dlo_course.paths import DATA_DIR

SHIPPED_AGENT = DATA_DIR / "checkpoints" / "nodes4"


def fails_clearly(args: list[str], *expected: str) -> str:
    """Run the command line; it must exit with a click error (code 1) that holds every
    ``expected`` piece, without a traceback."""
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit), result.exception  # not an exception
    assert "Traceback" not in result.output
    for piece in expected:
        assert piece in result.output, result.output
    return result.output


def truncated_copy(source, dest, keep: float = 0.5):
    data = source.read_bytes()
    dest.write_bytes(data[:int(len(data) * keep)])
    return dest


@pytest.fixture
def goal_files(tmp_path):
    goals = np.full((3, 4, 3), 0.5)
    np.save(tmp_path / "goals.npy", goals)
    np.savez(tmp_path / "goals.npz", goals=goals)
    return tmp_path / "goals.npy", tmp_path / "goals.npz"


@pytest.mark.parametrize("name", ["goals.npy", "goals.npz"])
def test_evaluate_with_a_truncated_goal_file(tmp_path, goal_files, name):
    source = dict(zip(("goals.npy", "goals.npz"), goal_files))[name]
    bad = truncated_copy(source, tmp_path / f"cut_{name}")
    fails_clearly(["evaluate", "--agent", str(SHIPPED_AGENT), "--database", str(bad),
                   "--episodes", "1"], str(bad), "not a readable")


def test_evaluate_with_a_truncated_database(tmp_path):
    bad = truncated_copy(DATA_DIR / "databases" / "small.npz", tmp_path / "small_cut.npz",
                         keep=0.3)
    fails_clearly(["evaluate", "--agent", str(SHIPPED_AGENT), "--database", str(bad),
                   "--episodes", "1"], str(bad), "not a readable goal file")
    # A readable archive without the database's arrays.
    np.savez(tmp_path / "other.npz", something=np.zeros(3))
    fails_clearly(["evaluate", "--agent", str(SHIPPED_AGENT), "--database",
                   str(tmp_path / "other.npz"), "--episodes", "1"], "no 'tip' array")


@pytest.mark.parametrize("flag", ["--agent", "--checkpoint"])
def test_evaluate_with_a_corrupt_actor_file(tmp_path, flag):
    agent = tmp_path / "agent"
    shutil.copytree(SHIPPED_AGENT, agent)
    truncated_copy(SHIPPED_AGENT / "actor.pt", agent / "actor.pt")
    for given in (agent, agent / "actor.pt"):
        fails_clearly(["evaluate", flag, str(given), "--episodes", "1"],
                      "is not a readable actor file")
    (agent / "actor.pt").write_text("not a network")
    fails_clearly(["evaluate", flag, str(agent), "--episodes", "1"],
                  "is not a readable actor file")


def test_reproduce_with_a_corrupt_agent(tmp_path):
    agents = tmp_path / "agents"
    shutil.copytree(DATA_DIR / "checkpoints", agents)
    for n in (2, 4, 6):  # whichever it evaluates first fails at once
        truncated_copy(agents / f"nodes{n}" / "actor.pt", agents / f"nodes{n}" / "actor.pt")
    fails_clearly(["reproduce", "--agents", str(agents), "--out", str(tmp_path / "report"),
                   "--episodes", "1"], "is not a readable actor file")


@pytest.fixture
def pendulum_run(tmp_path):
    """A finished one-episode Pendulum run with its resume state."""
    out = tmp_path / "run"
    result = CliRunner().invoke(main, ["train", "--env", "Pendulum-v1", "--episodes", "1",
                                       "--steps-per-episode", "5", "--out", str(out),
                                       "--no-progress"])
    assert result.exit_code == 0, result.output
    return out


def resume(run, episodes="2"):
    return ["train", "--env", "Pendulum-v1", "--episodes", episodes, "--steps-per-episode",
            "5", "--out", str(run), "--resume", "--no-progress"]


def test_resume_with_a_corrupt_resume_state(pendulum_run):
    state = pendulum_run / "checkpoints"
    pointer = state / "latest.json"
    good_pointer = pointer.read_text()
    pointer.write_text(good_pointer[:10])
    fails_clearly(resume(pendulum_run), "latest.json is not valid JSON")
    pointer.write_text("{}")
    fails_clearly(resume(pendulum_run), "latest.json is corrupt: it has no 'checkpoint'")
    pointer.write_text(good_pointer)

    shared = state / "episode000001" / "shared.pt"
    good_shared = shared.read_bytes()
    truncated_copy(shared, shared)
    fails_clearly(resume(pendulum_run), "shared.pt is not a readable resume state",
                  "--overwrite")
    shared.write_bytes(good_shared)
    (state / "episode000001" / "state_rank0.pt").unlink()
    fails_clearly(resume(pendulum_run), "state_rank0.pt is missing")


def test_a_corrupt_config_json_in_a_run_directory(pendulum_run, tmp_path):
    (pendulum_run / "config.json").write_text('{"config": {"episodes": ')
    fails_clearly(["ship", str(pendulum_run), str(tmp_path / "shipped")],
                  "config.json is not valid JSON")
    (pendulum_run / "config.json").write_text('{"config": {"no_such_field": 1}}')
    fails_clearly(["ship", str(pendulum_run), str(tmp_path / "shipped")],
                  "config.json does not hold a valid training configuration")
    # Resuming rewrites config.json from the configuration: the run continues.
    result = CliRunner().invoke(main, resume(pendulum_run))
    assert result.exit_code == 0, result.output


def test_plot_with_a_truncated_progress_log(pendulum_run, tmp_path):
    progress = pendulum_run / "progress.csv"
    lines = progress.read_text().splitlines()
    progress.write_text("\n".join(lines[:-1] + [lines[-1][:5]]) + "\n")
    fails_clearly(["plot", str(pendulum_run), "--out", str(tmp_path / "c.png")],
                  "progress.csv is truncated or corrupt")
    progress.write_text("nothing,here\n1,2\n")
    fails_clearly(["plot", str(pendulum_run), "--out", str(tmp_path / "c.png")],
                  "is not a progress log")


@pytest.fixture
def corrupt_shipped_database(tmp_path, monkeypatch):
    """The shipped databases folder with a truncated small.npz."""
    folder = tmp_path / "databases"
    folder.mkdir()
    truncated_copy(DATA_DIR / "databases" / "small.npz", folder / "small.npz")
    monkeypatch.setattr(database, "DATABASE_DIR", folder)
    return folder / "small.npz"


def test_database_commands_with_a_corrupt_database(corrupt_shipped_database, tmp_path):
    fails_clearly(["plot-boxes", "--out", str(tmp_path / "boxes.png")],
                  "small.npz is not a readable deformation database")
    fails_clearly(["demo", "--goals", "small", "--out", str(tmp_path / "demo.png")],
                  "small.npz is not a readable deformation database")
    fails_clearly(["evaluate", "--agent", str(SHIPPED_AGENT), "--database", "small",
                   "--episodes", "1"], "small.npz is not a readable deformation database")
