"""The README's commands, run as a user runs them: a fresh process, the shell's environment
without thread variables or the course's own (tests/user_env.py), torch at its default thread
count, and a timeout that turns a hang into a failure.

Every command line of the README's "Quick start", "Command line" and "Several cores, and a
cluster" sections is in :data:`COMMANDS`, either with the small variant that runs here (fewer
episodes and actions, outputs into the test's folder) or with the reason it does not (hours of
simulation, or a scheduler). A README line that is not in the table, or a table entry that is
no longer in the README, fails the fast test below, so the two cannot drift apart.

Why it exists: the grader, the trainer and MPI ranks all run torch on one thread, so a hang
that only happens with several threads (a fork after an OpenMP parallel region,
dlo_course/snapshot.py) passed every other test while `dlo-course evaluate` hung for users.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from dlo_course.paths import REPO_ROOT
from user_env import user_environment

BIN = Path(sys.executable).parent
README = REPO_ROOT / "README.md"
SECTIONS = ("Quick start", "Command line", "Several cores, and a cluster")


@dataclass(frozen=True)
class Run:
    """The command that runs in place of a README line: ``{tmp}`` is the test's folder,
    ``{run}`` the smoke run trained by the README's own `mpiexec ... train` line (its
    variant below), ``files`` are written into ``{tmp}`` first, ``makes`` must exist after."""

    command: str
    timeout: float = 240
    files: dict[str, str] = field(default_factory=dict)
    makes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Long:
    """A README line that does not run here, and why."""

    reason: str


SMOKE_TRAIN = "mpiexec -n 2 dlo-course train --preset smoke --nodes 4 --out runs/smoke4"
MAIN_JOB = "the main job, about 20 minutes on 2 cores (timed in a fresh clone: " \
           "benchmarks/results/reproduction_time_default.txt)"

COMMANDS: dict[str, Run | Long] = {
    # Quick start
    'python3 -m venv .venv && .venv/bin/pip install -c constraints.txt -e ".[mpi]" && '
    '.venv/bin/mpiexec -n 2 .venv/bin/dlo-course reproduce':
        Long("an install and " + MAIN_JOB),
    'python3 -m venv .venv && .venv/bin/pip install -c constraints.txt -e ".[test,notebooks]" '
    '&& .venv/bin/python -m pytest -n auto --dist loadgroup':
        Long("the install and this very suite: .ci/run runs it on a fresh machine"),
    # Command line
    "dlo-course mesh": Run("dlo-course mesh --out {tmp}/rod.vtk", makes=("rod.vtk",)),
    "dlo-course database --box small":
        Run("dlo-course database --box small --limit 3 --out {tmp}/small.npz",
            makes=("small.npz",)),
    "dlo-course database --box small --settle 15 --out small_settled.npz":
        Run("dlo-course database --box small --settle 15 --limit 2 --out {tmp}/settled.npz",
            makes=("settled.npz",)),
    "dlo-course plot-boxes": Run("dlo-course plot-boxes --out {tmp}/fig3.png",
                                 makes=("fig3.png",)),
    "dlo-course demo": Run("dlo-course demo --steps 4 --out {tmp}/demo.png",
                           makes=("demo.png",)),
    "dlo-course demo --agent data/checkpoints/nodes4":
        Run("dlo-course demo --agent data/checkpoints/nodes4 --steps 4 --out {tmp}/agent.png",
            makes=("agent.png",)),
    "dlo-course demo --agent RUN_DIR --database small-test --goal-index 15 --goal-index 26":
        Run("dlo-course demo --agent {run} --database small-test --goal-index 15 "
            "--goal-index 26 --steps 3 --out {tmp}/goals.png", makes=("goals.png",)),
    "dlo-course demo --controller jacobian --episodes 3":
        Run("dlo-course demo --controller jacobian --episodes 2 --steps 3 "
            "--out {tmp}/jacobian.png", makes=("jacobian.png",)),
    "dlo-course bench env": Run("dlo-course bench env", timeout=480),
    "dlo-course train --preset smoke":
        Run("dlo-course train --preset smoke --out {tmp}/smoke", makes=("smoke/actor.pt",)),
    "dlo-course train --list-presets": Run("dlo-course train --list-presets"),
    "dlo-course train --config exp.toml --seed 3 --print-config":
        Run("dlo-course train --config {tmp}/exp.toml --seed 3 --print-config",
            files={"exp.toml": 'preset = "smoke"\nepisodes = 3\n'}),
    "dlo-course train --preset recipe --tensorboard":
        Long("hours of training; --tensorboard itself: tests/test_cli_logging.py"),
    "dlo-course ship RUN_DIR data/checkpoints/nodes4 --actor best":
        Run("dlo-course ship {run} {tmp}/shipped --actor best",
            makes=("shipped/actor.pt", "shipped/record.json", "shipped/validated")),
    "dlo-course plot RUN_DIR ... [--aggregate-seeds] [--x transitions]":
        Run("dlo-course plot {run} --x transitions --out {tmp}/curves.png",
            makes=("curves.png",)),
    "dlo-course evaluate --agent RUN_DIR --database large --threshold 0.03 [--no-reinit]":
        Run("dlo-course evaluate --agent {run} --database large --threshold 0.03 --no-reinit "
            "--episodes 3 --max-steps 5"),
    "dlo-course evaluate --controller jacobian --nodes 4 --database small-test":
        Run("dlo-course evaluate --controller jacobian --nodes 4 --database small-test "
            "--episodes 2 --max-steps 5"),
    "mpiexec -n 2 dlo-course reproduce": Long(MAIN_JOB),
    "mpiexec -n 2 dlo-course reproduce --episodes 100 --whole-database with --controller "
    "jacobian --out docs/reproduction": Long("the committed report: hours on 2 cores"),
    "mpiexec -n 2 dlo-course reproduce --episodes 20":
        Long("about 10 minutes; `dlo-course reproduce` below runs the same code on one process"),
    "dlo-course reproduce":
        Run("dlo-course reproduce --nodes 4 --episodes 1 --max-steps 3 --whole-database none "
            "--out {tmp}/reproduction", makes=("reproduction/table1.csv",)),
    "mpiexec -n 32 dlo-course reproduce --episodes 1000": Long("32 ranks, a cluster's job"),
    "mpiexec -n 2 dlo-course reproduce --train --preset recipe": Long("days of training"),
    "mpiexec -n 2 dlo-course reproduce --nodes 6 --agents runs/mine":
        Long("needs the user's own agents; --nodes and --agents: tests/test_reproduce.py"),
    "dlo-course reproduce --preset smoke":
        Long("trains three agents first (minutes); the same pipeline with the smoke preset runs "
             "in tests/test_reproduce.py's cluster test, and `dlo-course reproduce` above runs "
             "its evaluation in one process, as here"),
    # Several cores, and a cluster
    SMOKE_TRAIN:
        Run("mpiexec -n 2 dlo-course train --preset smoke --nodes 4 --out {tmp}/smoke4 "
            "--validate-every 1 --validation-goals 2 --validation-steps 3",
            makes=("smoke4/actor.pt", "smoke4/best_actor.pt")),
    "mpiexec -n 2 dlo-course evaluate --agent runs/smoke4 --database large --episodes 100":
        Run("mpiexec -n 2 dlo-course evaluate --agent {run} --database large --episodes 4 "
            "--max-steps 5"),
    "sbatch scripts/cluster/paper.sbatch": Long("needs SLURM"),
    'LAUNCH="mpiexec -hosts node1,node2" bash scripts/cluster/paper.sbatch':
        Long("runs with the smoke preset and `mpiexec -hosts localhost,localhost` in "
             "tests/test_reproduce.py::test_cluster_script_runs_the_whole_pipeline_with_the_"
             "smoke_preset"),
}
"""Every README command of :data:`SECTIONS`, as written there (its comment dropped)."""

ISSUE_48 = "dlo-course evaluate --checkpoint data/checkpoints/nodes4 --database small-test " \
           "--episodes 4"
"""The command that hung for users (issue 48): run exactly as written, from the repository."""


def readme_commands(text: str) -> list[str]:
    """The command lines of the ```bash blocks in the README's :data:`SECTIONS`, without
    their trailing comments."""
    commands = []
    for section in re.split(r"^## ", text, flags=re.M)[1:]:
        title, _, body = section.partition("\n")
        if title.strip() not in SECTIONS:
            continue
        for block in re.findall(r"```bash\n(.*?)```", body, flags=re.S):
            for line in block.splitlines():
                command = re.sub(r"\s+#\s.*$", "", line).strip()
                if command:
                    commands.append(command)
    return commands


def test_every_readme_command_is_run_here_or_says_why_not():
    in_readme = readme_commands(README.read_text())
    assert len(in_readme) >= 20, "the README's sections were not found"
    assert not [c for c in in_readme if c not in COMMANDS], \
        "README commands this file does not know: add each to COMMANDS"
    assert not [c for c in COMMANDS if c not in in_readme], \
        "COMMANDS entries no longer in the README: remove or update them"


def run_as_user(command: str, tmp: Path, timeout: float,
                run: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``command`` from the repository root in a user's environment; a hang fails."""
    argv = shlex.split(command.format(tmp=tmp, run=run))
    if argv[0] in ("dlo-course", "mpiexec"):
        argv[0] = str(BIN / argv[0])
    if argv[0].endswith("mpiexec") and "dlo-course" in argv:
        argv[argv.index("dlo-course")] = str(BIN / "dlo-course")
    try:
        done = subprocess.run(argv, cwd=REPO_ROOT, env=user_environment(), timeout=timeout,
                              capture_output=True, text=True)
    except subprocess.TimeoutExpired as err:
        pytest.fail(f"`{command}` did not finish in {timeout:.0f} s as a user runs it "
                    f"(a hang?); its output so far:\n{err.stdout or ''}\n{err.stderr or ''}")
    assert done.returncode == 0, f"`{command}` failed:\n{done.stdout}\n{done.stderr}"
    return done


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory) -> Path:
    """The README's 2-rank smoke training (its variant in COMMANDS), for the commands that
    take a RUN_DIR."""
    if not (BIN / "mpiexec").exists():
        pytest.skip("no mpiexec in this environment (the mpi extra)")
    tmp = tmp_path_factory.mktemp("user_path_run")
    run_as_user(COMMANDS[SMOKE_TRAIN].command, tmp, COMMANDS[SMOKE_TRAIN].timeout)
    return tmp / "smoke4"


RUNNABLE = [c for c, what in COMMANDS.items() if isinstance(what, Run)]


@pytest.mark.slow
@pytest.mark.xdist_group("user_path")
@pytest.mark.parametrize("readme_command", RUNNABLE)
def test_readme_command_runs_as_a_user_runs_it(readme_command, tmp_path, request):
    what = COMMANDS[readme_command]
    uses_run = "{run}" in what.command or readme_command == SMOKE_TRAIN
    if "mpiexec" in what.command and not (BIN / "mpiexec").exists():
        pytest.skip("no mpiexec in this environment (the mpi extra)")
    run = request.getfixturevalue("smoke_run") if uses_run else None
    if readme_command == SMOKE_TRAIN:  # the fixture ran it
        tmp = run.parent
    else:
        tmp = tmp_path
        for name, text in what.files.items():
            (tmp / name).write_text(text)
        run_as_user(what.command, tmp, what.timeout, run)
    missing = [m for m in what.makes if not (tmp / m).exists()]
    assert not missing, f"`{what.command}` did not write {missing}"


@pytest.mark.slow
def test_the_evaluate_command_that_hung_finishes_in_seconds_as_a_user_runs_it(tmp_path):
    done = run_as_user(ISSUE_48, tmp_path, timeout=120)
    assert "4 episodes of at most 30 steps" in done.stdout and "done " in done.stdout, \
        done.stdout


README_PYTHON = re.search(r"## The environment\n\n```python\n(.*?)```", README.read_text(),
                          flags=re.S)


@pytest.mark.slow
def test_the_readme_environment_snippet_runs_as_a_user_runs_it(tmp_path):
    assert README_PYTHON, "the README's environment snippet was not found"
    code = README_PYTHON.group(1) + "\nassert image.ndim == 3 and obs.shape == (30,)\n"
    try:
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, timeout=180,
                              env=user_environment(), capture_output=True, text=True)
    except subprocess.TimeoutExpired:
        pytest.fail("the README's environment snippet did not finish in 180 s")
    assert done.returncode == 0, done.stderr
