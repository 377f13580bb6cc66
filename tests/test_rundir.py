"""A training run on disk (dlo_course.rundir): one atomic write, the names of the files, and
the formats of the runs and agents written before this module."""

import json

import pytest

from dlo_course import evaluation, rundir
from dlo_course.paths import AGENTS_DIR, REPO_ROOT


def test_an_atomic_write_that_fails_leaves_the_old_file(tmp_path):
    path = tmp_path / "best.json"
    rundir.write_json({"episode": 1}, path)

    def crash(tmp):
        tmp.write_text('{"episo')  # half written, then the run is killed
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rundir.atomic_write(path, crash)
    assert rundir.read_json(path) == {"episode": 1}


def test_keep_episodes_cuts_a_log(tmp_path):
    log = tmp_path / rundir.PROGRESS_FILE
    log.write_text("episode,reward_mean\n1,-3\n2,-2\n3,-1\n")
    rundir.keep_episodes(log, 2)
    assert log.read_text().splitlines() == ["episode,reward_mean", "1,-3", "2,-2"]




@pytest.mark.parametrize("n_nodes", [2, 4, 6])
def test_the_shipped_agents_still_load(n_nodes):
    folder = rundir.agent_dir(AGENTS_DIR, n_nodes)
    actor, nodes = evaluation.load_actor(folder, n_nodes)
    assert nodes == n_nodes and actor.init_kwargs["obs_dim"] == 6 + 6 * n_nodes
    record = rundir.training_record(AGENTS_DIR, n_nodes)
    assert record == json.loads((folder / rundir.RECORD_FILE).read_text())
    assert rundir.load_config(folder).env_kwargs["n_nodes"] == n_nodes


def _resumable_runs():
    runs = REPO_ROOT / "runs"
    return sorted(p for p in runs.glob("*/") if (p / rundir.RESUME_DIR / rundir.RESUME_POINTER)
                  .is_file()) if runs.is_dir() else []


@pytest.mark.skipif(not _resumable_runs(), reason="no run with a resume state in runs/")
def test_the_runs_on_disk_are_read_with_the_names_of_this_module():
    # Read only: a run in runs/ may be training right now.
    for run in _resumable_runs():
        pointer = rundir.read_json(run / rundir.RESUME_DIR / rundir.RESUME_POINTER)
        state = run / rundir.RESUME_DIR / pointer["checkpoint"]
        if not state.is_dir():
            continue  # replaced between the two reads by a run that is training
        assert (state / rundir.SHARED_STATE_FILE).is_file()
        assert (state / "state_rank0.pt").is_file()
        assert rundir.resumable_episodes(run) == pointer["episodes_done"]
        config = rundir.load_config(run)
        assert config.out_dir and rundir.run_record(run)["seed"] == config.seed
