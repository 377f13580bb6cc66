"""`dlo-course plot`: learning curves averaged over seeds, against episodes or transitions."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from dlo_course.cli import main
from dlo_course.config import preset
from dlo_course.plots import plot_learning_curves, seed_curve, seed_groups
from dlo_course.rundir import PROGRESS_COLUMNS, read_progress


def fake_run(folder, seed, rewards, lengths, batch_size=16):
    """A run directory with a config.json and a progress.csv of the given episodes."""
    folder.mkdir(parents=True)
    config = preset("smoke", seed=seed, out_dir=str(folder))
    config.ddpg.batch_size = batch_size
    (folder / "config.json").write_text(json.dumps({"config": config.to_dict(),
                                                    "n_agents": 2}))
    with open(folder / "progress.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=PROGRESS_COLUMNS)
        writer.writeheader()
        transitions = np.cumsum(lengths)
        for episode, (reward, total) in enumerate(zip(rewards, transitions), start=1):
            writer.writerow({"episode": episode, "transitions": int(total),
                             "reward_mean": reward, "reward_min": reward - 1,
                             "reward_max": reward + 1})
    return folder


@pytest.fixture
def runs(tmp_path):
    return [fake_run(tmp_path / "a0", 0, [-3.0, -2.0, -1.0], [10, 10, 10]),
            fake_run(tmp_path / "b0", 0, [-5.0, -5.0], [20, 20], batch_size=32),
            fake_run(tmp_path / "a1", 1, [-5.0, -4.0, -3.0, -2.0], [20, 20, 20, 20]),
            fake_run(tmp_path / "a2", 2, [-4.0, -3.0, -2.0], [10, 30, 10])]


def test_runs_that_differ_only_by_seed_are_grouped(runs):
    a0, b0, a1, a2 = runs
    assert seed_groups(runs) == [[a0, a1, a2], [b0]]
    broken = a0.parent / "broken"
    broken.mkdir()
    (broken / "config.json").write_text("{not json")
    assert seed_groups([a0, broken, a1]) == [[a0, a1], [broken]]


def test_the_seed_curve_is_the_mean_and_spread_over_seeds(runs):
    a0, _, a1, a2 = runs
    progresses = [read_progress(r) for r in (a0, a1, a2)]
    grid, mean, spread = seed_curve(progresses, "episode")
    assert grid.tolist() == [1, 2, 3]  # the episodes every seed reached
    values = np.array([[-3, -2, -1], [-5, -4, -3], [-4, -3, -2]], float)
    np.testing.assert_allclose(mean, values.mean(axis=0))
    np.testing.assert_allclose(spread, values.std(axis=0, ddof=1))

    grid, mean, spread = seed_curve(progresses, "transitions", points=5)
    assert (grid[0], grid[-1]) == (20, 30)  # every run covers 20..30 transitions
    at_30 = [np.interp(30, p["transitions"], p["reward_mean"]) for p in progresses]
    assert mean[-1] == pytest.approx(np.mean(at_30))
    grid, mean, spread = seed_curve(progresses[:1], "episode")
    assert not spread.any()
    with pytest.raises(ValueError, match="x must be one of"):
        seed_curve(progresses, "wall_time")


def test_the_figure_has_one_curve_per_group(runs, tmp_path):
    fig = plot_learning_curves(runs, aggregate_seeds=True, x="transitions")
    ax = fig.axes[0]
    assert [line.get_label() for line in ax.get_lines()][1].startswith("b0")
    assert ax.get_lines()[0].get_label().endswith("3 seeds")
    assert ax.get_xlabel().startswith("transitions")
    with pytest.raises(ValueError, match=r"one label per group of seeds \(2\), got 1"):
        plot_learning_curves(runs, aggregate_seeds=True, labels=["only one"])
    assert len(plot_learning_curves(runs).axes[0].get_lines()) == 4  # as before


def test_plot_command(runs, tmp_path):
    out = tmp_path / "curves.png"
    result = CliRunner().invoke(main, ["plot", *map(str, runs), "--aggregate-seeds",
                                       "--x", "transitions", "--label", "A", "--label", "B",
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.stat().st_size > 0
    result = CliRunner().invoke(main, ["plot", *map(str, runs), "--aggregate-seeds",
                                       "--label", "A", "--out", str(out)])
    assert result.exit_code == 1 and "one label per group of seeds" in result.output
