"""The reproduction: Table I's layout, the report, and the whole pipeline in its smoke size."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlo_course.cli import main
from dlo_course.reproduce import read_paper_table, table1_cells, write_table

REPO = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent


def test_the_24_settings_match_the_papers_table():
    cells = table1_cells()
    paper = read_paper_table()
    assert len(cells) == 24 == len(paper)
    assert {c.key for c in cells} == set(paper)
    assert paper[("with", 4, "large", 0.05)]["done_percent"] == 97.2
    assert paper[("without", 6, "small", 0.05)]["mean_distance"] == 0.08669
    some = table1_cells((6, 2))  # `reproduce --nodes`: those rows, in the paper's order
    assert len(some) == 16 and [c for c in cells if c.nodes != 4] == some


def test_table_sets_our_numbers_beside_the_papers(tmp_path):
    paper = read_paper_table()
    rows = [{"cell": c, "episodes": 10, "done_percent": 90.0, "done_ci_low": 59.6,
             "done_ci_high": 98.2, "mean_distance": 0.04, "std_distance": 0.01,
             "best_distance": 0.02, "mean_steps": 8.0} for c in table1_cells()]
    csv_path, md_path = write_table(rows, paper, tmp_path)
    with open(csv_path, newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 24
    first = table[0]  # with, 2 nodes, small, 0.05: the paper has 99.5 %
    assert float(first["paper_done_percent"]) == 99.5
    assert float(first["done_diff"]) == pytest.approx(90.0 - 99.5)
    assert float(first["mean_diff"]) == pytest.approx(0.04 - 0.03010)
    assert md_path.read_text().count("\n") == 26  # header, rule, 24 settings
    # The paper's 99.5 % lies above our interval 59.6-98.2: below the paper, significantly.
    assert first["verdict"] == "below"


def test_verdicts_against_the_papers_done_percent():
    from dlo_course.reproduce import verdict

    row = {"done_ci_low": 90.0, "done_ci_high": 99.0}
    assert verdict(row, 99.5) == "below"
    assert verdict(row, 95.0) == verdict(row, 90.0) == verdict(row, 99.0) == "within"
    assert verdict(row, 80.0) == "above"


def test_done_verdict_takes_the_wilson_interval_in_percent():
    from dlo_course.evaluation import wilson_interval
    from dlo_course.reproduce import done_verdict

    low, high = (100 * x for x in wilson_interval(87, 100))  # 79.0 to 92.2
    assert done_verdict(87, 100, low - 0.1) == "above"      # the paper below our interval
    assert done_verdict(87, 100, low) == done_verdict(87, 100, high) == "within"  # ends in it
    assert done_verdict(87, 100, high + 0.1) == "below"
    assert done_verdict(0, 20, 0.0) == done_verdict(20, 20, 100.0) == "within"
    assert done_verdict(20, 20, 99.0) == "within" and done_verdict(1000, 1000, 99.0) == "above"


def test_goal_sources_of_the_two_protocols():
    from dlo_course.reproduce import goal_source

    assert goal_source("small", "test") == "small-test"
    assert goal_source("large", "whole") == "large"
    with pytest.raises(ValueError):
        goal_source("small", "random")


def test_reproduce_flag_errors():
    runner = CliRunner()
    result = runner.invoke(main, ["reproduce", "--preset", "laptop"])
    assert result.exit_code != 0 and "--train" in result.output
    result = runner.invoke(main, ["reproduce", "--train"])
    assert result.exit_code != 0 and "--preset" in result.output
    result = runner.invoke(main, ["reproduce", "--checkpoints", "/nonexistent", "--episodes", "1"])
    assert result.exit_code != 0 and "no trained agent" in result.output


@pytest.mark.slow
@pytest.mark.mpi
def test_cluster_script_runs_the_whole_pipeline_with_the_smoke_preset(tmp_path):
    """The SLURM script, outside SLURM, with the plain `mpiexec -hosts` launcher: smoke
    training on 2 ranks, then Table I's settings split over the ranks (episodes of at most 5
    actions: the pipeline, not the agents, is under test). One node count (NODES_LIST, the
    script's `reproduce --nodes`): the other two run the same code, and cost 4 minutes."""
    out = tmp_path / "paper"
    env = dict(os.environ, VENV=str(BIN.parent), PRESET="smoke", NTASKS="2", EPISODES="2",
               MAX_STEPS="5", OUT=str(out), NODES_LIST="2",
               LAUNCH=f"{BIN / 'mpiexec'} -hosts localhost,localhost",
               PATH=f"{BIN}:{os.environ['PATH']}")
    subprocess.run(["bash", str(REPO / "scripts" / "cluster" / "paper.sbatch")], env=env,
                   check=True, timeout=900, cwd=tmp_path, capture_output=True)
    report = out / "report"
    with open(report / "table1.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8 and all(int(r["episodes"]) == 2 and r["nodes"] == "2" for r in rows)
    with open(report / "table1_whole_database.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 4  # the cells with reinitialisation
    for name in ("table1.md", "report.md", "fig4_learning_curves.png", "fig5_deformation.png"):
        assert (report / name).stat().st_size > 0
    assert [p.name for p in out.glob("nodes*")] == ["nodes2"]
    assert (out / "nodes2" / "actor.pt").is_file()
    text = (report / "report.md").read_text()
    assert "| 2 | 2 | 2 x 20 |" in text and "Node counts: 2 only" in text  # ranks, episodes x steps


def test_ship_run_copies_the_networks_and_writes_the_training_record(tmp_path):
    from dlo_course.config import DDPGConfig, TrainConfig
    from dlo_course.reproduce import course_options
    from dlo_course.rundir import ship_run, training_record
    from dlo_course.trainer import train

    run = train(TrainConfig(env_id="Pendulum-v1", env_kwargs={}, episodes=2,
                            steps_per_episode=20, out_dir=str(tmp_path / "run"), seed=4,
                            updates_per_step=2,
                            ddpg=DDPGConfig(hidden_sizes=(8,), batch_size=8,
                                            normalize_obs=True)), progress=False)
    dest = ship_run(run, tmp_path / "checkpoints" / "nodes2", note="test")
    assert sorted(p.name for p in dest.iterdir()) == sorted(
        ["actor.pt", "critic.pt", "config.json", "progress.csv", "record.json"])
    record = training_record(tmp_path / "checkpoints", 2)
    assert record["ranks"] == 1 and record["seed"] == 4 and record["note"] == "test"
    assert record["episodes_per_agent"] == 2 and record["transitions"] == 40
    assert record["commit"]  # this test runs from a git checkout
    assert course_options(record) == "input scaling, 2 updates/step, batch 8"
    assert course_options({}) == "none"
    with pytest.raises(FileNotFoundError, match="not a finished run"):
        ship_run(tmp_path / "nowhere", tmp_path / "x")
    # A run killed after its last checkpoint: its curve is shipped up to that checkpoint,
    # like its networks.
    with open(run / "progress.csv") as f:
        lines = f.read().splitlines()
    with open(run / "progress.csv", "a") as f:
        f.write(lines[-1].replace("2,", "3,", 1) + "\n")  # an episode 3, never checkpointed
    killed = ship_run(run, tmp_path / "killed")
    assert json.loads((killed / "record.json").read_text())["episodes_per_agent"] == 2


def test_evaluation_runs_are_kept_and_reused(tmp_path, monkeypatch):
    """A stopped reproduction resumes: a finished run's results are read back, not re-run,
    for the same agent and settings; another agent (other weights) is evaluated afresh."""
    import shutil

    import dlo_course.reproduce as reproduce
    from dlo_course.paths import AGENTS_DIR

    agents = tmp_path / "agents"
    shutil.copytree(AGENTS_DIR / "nodes2", agents / "nodes2")
    cells = [c for c in table1_cells() if (c.nodes, c.database, c.reinit) == (2, "small", "with")]
    first = reproduce.evaluate_cells(agents, episodes=1, max_steps=2, seed=0, cells=cells,
                                     cache=tmp_path / "runs")
    assert [r["cell"] for r in first] == cells and len(list((tmp_path / "runs").iterdir())) == 1
    assert reproduce.evaluation_minutes(first) == pytest.approx(first[0]["minutes"])

    def must_not_run(*args, **kwargs):
        raise AssertionError("a kept run was evaluated again")

    monkeypatch.setattr(reproduce, "evaluate_thresholds", must_not_run)
    again = reproduce.evaluate_cells(agents, episodes=1, max_steps=2, seed=0, cells=cells,
                                     cache=tmp_path / "runs")
    assert [{k: v for k, v in r.items()} for r in again] == first
    # the minutes are said on the ranks that ran them, not on this invocation's
    assert first[0]["ranks"] == 1 and "on 1 rank(s)" in reproduce._time_note(first)
    saved = next((tmp_path / "runs").iterdir())
    kept = json.loads(saved.read_text())

    def note_from_cache():
        return reproduce._time_note(reproduce.evaluate_cells(
            agents, episodes=1, max_steps=2, seed=0, cells=cells, cache=tmp_path / "runs"))

    saved.write_text(json.dumps({**kept, "ranks": 32}))
    assert "on 32 rank(s)" in note_from_cache()
    del kept["ranks"]  # a run cached before the count was recorded
    saved.write_text(json.dumps(kept))
    assert "evaluation on a rank count not recorded" in note_from_cache()
    with pytest.raises(AssertionError, match="evaluated again"):  # other episodes: a new run
        reproduce.evaluate_cells(agents, episodes=2, max_steps=2, seed=0, cells=cells,
                                 cache=tmp_path / "runs")
    shutil.copy(AGENTS_DIR / "nodes4" / "actor.pt", agents / "nodes2" / "actor.pt")
    with pytest.raises(AssertionError, match="evaluated again"):  # other weights: a new run
        reproduce.evaluate_cells(agents, episodes=1, max_steps=2, seed=0, cells=cells,
                                 cache=tmp_path / "runs")


@pytest.mark.slow
def test_cli_reproduce_evaluates_a_controller_beside_the_agents(tmp_path, monkeypatch):
    """`dlo-course reproduce --controller jacobian`: the controller's cells beside the agents',
    in its own table and in the report. Cheap: two cells (one shared run each for the agents
    and for the controller), one episode of one action, no Fig. 5 simulation."""
    import dlo_course.reproduce as reproduce

    cells = [reproduce.Cell("with", 2, "small", 0.05), reproduce.Cell("with", 2, "small", 0.03),
             reproduce.Cell("without", 2, "small", 0.05)]
    monkeypatch.setattr(reproduce, "table1_cells", lambda nodes=(2,): cells)
    monkeypatch.setattr(reproduce, "plot_deformation",
                        lambda agent, out, **kwargs: Path(out).write_bytes(b""))
    out = tmp_path / "report"
    result = CliRunner().invoke(main, [
        "reproduce", "--out", str(out), "--episodes", "1", "--max-steps", "1",
        "--whole-database", "none", "--controller", "jacobian"])
    assert result.exit_code == 0, result.output
    with open(out / "table1_jacobian.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    # by default the controller plays the cells with reinitialisation only (--controller-cells)
    assert [(r["nodes"], r["threshold"], r["episodes"]) for r in rows] == [
        ("2", "0.05", "1"), ("2", "0.03", "1")]
    assert not list((out / "runs").glob("jacobian_test_without_*.json"))
    assert len(list((out / "runs").glob("test_without_n2_small_*.json"))) == 1  # the agent's
    assert "the `jacobian` controller" in (out / "report.md").read_text()
    assert len(list((out / "runs").glob("jacobian_test_with_n2_small_*.json"))) == 1
    assert len(list((out / "runs").glob("test_with_n2_small_*.json"))) == 1  # the agent's
    wrong = CliRunner().invoke(main, ["reproduce", "--controller", "nope"])
    assert wrong.exit_code != 0 and "nope" in wrong.output


def test_the_report_shows_the_seeds_table_beside_the_shipped_agents(tmp_path):
    """Issue 49: the report carries the committed seeds table for the shipped agents only."""
    from dlo_course.paths import AGENTS_DIR
    from dlo_course.reproduce import SEEDS_TABLE, seeds_section

    lines = "\n".join(seeds_section(AGENTS_DIR, (2, 4, 6)))
    assert "over training seeds" in lines and "| reinit | nodes |" in lines
    assert SEEDS_TABLE.read_text().splitlines()[0] not in lines  # its title is the report's
    assert seeds_section(tmp_path, (2, 4, 6)) == []  # other agents: the seeds are not theirs
    assert seeds_section(AGENTS_DIR, (4,)) == []
    assert seeds_section(AGENTS_DIR, (2, 4, 6), table=tmp_path / "none.md") == []
