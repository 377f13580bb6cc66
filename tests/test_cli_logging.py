"""The trainer's logger hook, and `dlo-course train --tensorboard`."""

from __future__ import annotations

import csv
import importlib.util
import math

import pytest
from click.testing import CliRunner

from dlo_course.cli import main
from dlo_course.config import preset
from dlo_course.trainer import TrainingLogger, train

HAS_TENSORBOARD = importlib.util.find_spec("tensorboard") is not None


class Recorder(TrainingLogger):
    def __init__(self):
        self.calls = []

    def open(self, run_dir, episodes_done):
        self.calls.append(("open", episodes_done))

    def episode(self, row):
        self.calls.append(("episode", dict(row)))

    def validation(self, row):
        self.calls.append(("validation", dict(row)))

    def close(self):
        self.calls.append(("close",))


def pendulum(tmp_path, **overrides):
    return preset("smoke", env_id="Pendulum-v1", env_kwargs={}, steps_per_episode=8,
                  out_dir=str(tmp_path / "run"), **overrides)


def test_the_logger_gets_the_rows_of_progress_csv_and_changes_nothing(tmp_path):
    recorder = Recorder()
    out = train(pendulum(tmp_path, episodes=2), progress=False, loggers=[recorder])
    with open(out / "progress.csv", newline="") as f:
        written = list(csv.DictReader(f))
    assert recorder.calls[0] == ("open", 0) and recorder.calls[-1] == ("close",)
    rows = [call[1] for call in recorder.calls if call[0] == "episode"]
    assert len(rows) == len(written) == 2
    for logged, row in zip(rows, written):
        for key, cell in row.items():
            value = logged[key]
            assert (cell == "" and math.isnan(value)) or float(cell) == pytest.approx(value)

    # The same run without a logger writes the same numbers (wall time aside).
    again = train(pendulum(tmp_path, episodes=2), progress=False, overwrite=True)
    with open(again / "progress.csv", newline="") as f:
        plain = list(csv.DictReader(f))
    for a, b in zip(written, plain):
        assert {k: v for k, v in a.items() if k != "wall_time"} == \
            {k: v for k, v in b.items() if k != "wall_time"}

    # Resumed: the logger is told where the run starts again.
    recorder = Recorder()
    train(pendulum(tmp_path, episodes=3), resume=True, progress=False, loggers=[recorder])
    assert recorder.calls[0] == ("open", 2)
    assert [call[1]["episode"] for call in recorder.calls if call[0] == "episode"] == [3]


@pytest.mark.skipif(HAS_TENSORBOARD, reason="tensorboard is installed")
def test_tensorboard_without_the_package_is_a_clear_error(tmp_path):
    result = CliRunner().invoke(main, ["train", "--env", "Pendulum-v1", "--episodes", "1",
                                       "--out", str(tmp_path / "run"), "--tensorboard",
                                       "--no-progress"])
    assert result.exit_code == 1
    assert "needs the tensorboard package" in result.output
    assert not (tmp_path / "run").exists()


@pytest.mark.skipif(not HAS_TENSORBOARD, reason="needs the tensorboard package")
def test_tensorboard_gets_the_episode_scalars(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out = tmp_path / "run"
    result = CliRunner().invoke(main, ["train", "--env", "Pendulum-v1", "--episodes", "2",
                                       "--steps-per-episode", "8", "--out", str(out),
                                       "--tensorboard", "--no-progress"])
    assert result.exit_code == 0, result.output
    events = EventAccumulator(str(out / "tensorboard"))
    events.Reload()
    rewards = events.Scalars("train/reward_mean")
    assert [e.step for e in rewards] == [1, 2]
    with open(out / "progress.csv", newline="") as f:
        written = [float(r["reward_mean"]) for r in csv.DictReader(f)]
    assert [e.value for e in rewards] == pytest.approx(written, rel=1e-6)
