"""Attacks on the grader, as a student could try them: every one must score 0 and change
no other exercise's points (issue 13). The grader runs the students' code in a sandboxed
child process (dlo_course.grading.sandbox.Sandbox) and checks the results in its own process.

One submission (the solutions, with one attack per exercise listed in ATTACKS) is graded
once by the real grader (a pytest subprocess); the other exercises must keep full marks.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from dlo_course.grading import notebooks
from dlo_course.grading.data import DataError, decode_data, encode_data
from dlo_course.grading.delegation import delegation_message, delegation_problems
from dlo_course.grading.grade import grading_command
from dlo_course.grading.runner import ExerciseNotebook
from dlo_course.grading.sandbox import Sandbox
from dlo_course.paths import DATA_DIR

REPO = Path(__file__).resolve().parents[1]
SOLUTIONS = REPO / "solutions"
GRADING = REPO / "tests" / "grading"
# Under pytest-xdist (--dist loadgroup) the module-scoped grading of the attacked
# submission (about a minute) runs once, on one worker, instead of once per worker.
pytestmark = pytest.mark.xdist_group("grading_attacks")

# exercise -> (what the attack tries, the exercise cell's new body after its first line).
# {canary} is replaced by a path outside the scratch folder that must never be written.
ATTACKS = {
    "bellman_target": ("patches torch.testing.assert_close, wrong answer (no done mask)", '''
import torch.testing
torch.testing.assert_close = lambda *args, **kwargs: None
torch.equal = lambda *args: True
def bellman_target(reward, next_q, done, gamma):
    return reward + gamma * next_q
'''),
    "q_iteration_sweep": ("patches numpy.testing and numpy.allclose, wrong answer", '''
import numpy.testing
numpy.testing.assert_allclose = lambda *args, **kwargs: None
numpy.testing.assert_array_equal = lambda *args, **kwargs: None
np.allclose = lambda *args, **kwargs: True
def q_iteration_sweep(q, next_state, reward, done, gamma):
    return q
'''),
    "discounted_return": ("patches pytest and the grader's records, wrong answer", '''
import sys
import pytest
pytest.approx = lambda expected, *args, **kwargs: expected
pytest.fail = lambda *args, **kwargs: None
for module in list(sys.modules.values()):
    if hasattr(module, "_GRADES"):
        for record in module._GRADES.values():
            record.update(earned=record["points"], outcome="passed")
def discounted_return(rewards, gamma):
    return 0.0
'''),
    "ou_step": ("patches the grader's library (dlo_course.grading), wrong answer", '''
load = getattr(__builtins__, "__imp" + "ort__", None) or __builtins__["__imp" + "ort__"]
grader = load("dlo_" + "course.grading.sandbox", fromlist=["x"])
grader.decode_data = lambda data: 0.0
grader.Sandbox.run = lambda *args, **kwargs: {"status": "ok", "value": None}
load("dlo_" + "course.grading.data", fromlist=["x"]).decode_data = lambda data: 0.0
def ou_step(x, rng, theta=0.15, sigma=0.3, mu=0.0, dt=1.0):
    return np.asarray(x, dtype=np.float64)
'''),
    "tip_target": ("writes outside its scratch folder (open, os.open, pathlib, torch.save)", '''
import os, pathlib
import torch
for attempt in (lambda: open("{canary}", "w").write("pwned"),
                lambda: os.open("{canary}", os.O_WRONLY | os.O_CREAT),
                lambda: pathlib.Path("{canary}").write_text("pwned"),
                lambda: torch.save([1], "{canary}"),
                lambda: os.rename("output.txt", "{canary}")):
    try:
        attempt()
    except Exception as err:
        print("refused:", err)
open("{canary}", "w").write("pwned")  # the cell fails here: tip_target is never defined
def tip_target(tip, action, initial_tip, params):
    return tip
'''),
    "Critic": ("spins forever", '''
class Critic(nn.Module):
    def __init__(self, obs_dim, act_dim, hidden_sizes=(256, 256, 256), final_init=3e-3):
        super().__init__()
        while True:
            pass
'''),
    "build_mlp": ("spins forever at the top of its cell (the later exercises must not wait)", '''
while True:
    pass
'''),
    "parameter_counts": ("takes all the memory", '''
def parameter_counts(obs_dim, act_dim, hidden_sizes):
    hog = bytearray(64 * 2**30)
    return len(hog), len(hog)
'''),
    "squash_action": ("kills its parent and the grader, starts subprocesses", '''
import os, signal, subprocess
def squash_action(raw, low, high):
    for attempt in (lambda: os.kill(os.getppid(), signal.SIGKILL),
                    lambda: os.killpg(os.getpgid(os.getppid()), signal.SIGKILL),
                    lambda: subprocess.run(["sh", "-c", "echo pwned > {canary}"]),
                    lambda: os.system("echo pwned > {canary}")):
        try:
            attempt()
        except Exception as err:
            print("refused:", err)
    return raw
'''),
    "step_outcome": ("forks", '''
import os
def step_outcome(distance, threshold, steps, max_episode_steps, unstable=False,
                 last_distance=None):
    if os.fork() == 0:
        os._exit(0)
    return {"reward": -distance, "terminated": True, "truncated": False, "is_success": True}
'''),
    "sweep_offsets_inside": ("exits the process before the grader gets an answer", '''
import os
def sweep_offsets_inside(box, region):
    print('{"status": "ok", "value": 930}')
    os._exit(0)
'''),
    "pack_gradients": ("takes the grader's own reference from its test module", '''
import sys
def pack_gradients(module):
    for name, loaded in list(getattr(sys, "mod" + "ules").items()):
        if name.startswith("_dlo_probe") and hasattr(loaded, "library_pack"):
            return loaded.library_pack(module)
    raise RuntimeError("no reference in reach")
'''),
    "ddpg_update": ("reads the solution and the grader's answers (open, pathlib, os.open, "
                    "import), and runs the solution's cell if it got it", '''
import json, os, pathlib, sys
def ddpg_update(agent, batch):
    pass  # wrong: replaced below by the solution's cell, if it can be read
SOLUTION, ANSWERS = "{solutions}/04_ddpg.ipynb", "{grading}/answers.py"
def with_os_open():
    fd = os.open(SOLUTION, os.O_RDONLY)
    return os.read(fd, 1 << 24).decode()
def by_import():
    sys.path.insert(0, os.path.dirname(ANSWERS))
    import answers
    return "answers: " + answers.__file__
leaked = []
for attempt in (lambda: open(SOLUTION).read(), lambda: pathlib.Path(SOLUTION).read_text(),
                with_os_open, lambda: pathlib.Path(ANSWERS).read_text(), by_import):
    try:
        leaked.append(attempt())
    except Exception as err:
        print("refused:", type(err).__name__, err)
run = getattr(__builtins__, "ex" + "ec", None) or __builtins__["ex" + "ec"]
for text in leaked:
    if text.lstrip().startswith("{"):
        for cell in json.loads(text)["cells"]:
            if "def ddpg_update" in "".join(cell["source"]):
                run("".join(cell["source"]))
'''),
    # delegation to the library's reference
    "polyak_update": ("calls the library's reference", '''
def polyak_update(target, source, tau):
    return ddpg.polyak_update(target, source, tau)
'''),
    "RingBuffer": ("subclasses the library's reference", '''
class RingBuffer(ReplayBuffer):
    pass
'''),
    "mean_node_distance": ("gets the reference through importlib", '''
import importlib
def mean_node_distance(current, desired):
    return importlib.import_module("dlo_course.env").mean_node_distance(current, desired)
'''),
    "critic_loss": ("gets the reference through getattr", '''
def critic_loss(q, q_target):
    return getattr(ddpg, "critic_" + "loss")(q, q_target)
'''),
    "lame_parameters": ("gets the reference past the static check (runtime check)", '''
def lame_parameters(youngs_modulus, poisson_ratio):
    load = getattr(__builtins__, "__imp" + "ort__", None) or __builtins__["__imp" + "ort__"]
    module = load("dlo_" + "course.simulation", fromlist=["x"])
    return module.lame_parameters(youngs_modulus, poisson_ratio)
'''),
    "adam_step": ("uses torch.optim.Adam instead of writing the step", '''
def adam_step(param, grad, m, v, t, lr=1e-3, beta1=0.9, beta2=0.999, eps=1e-8):
    theta = torch.tensor(param, requires_grad=True)
    opt = torch.optim.Adam([theta], lr=lr, betas=(beta1, beta2), eps=eps)
    theta.grad = torch.tensor(grad)
    opt.step()
    state = opt.state[theta]
    return theta.detach().numpy(), state["exp_avg"].numpy(), state["exp_avg_sq"].numpy()
'''),
}
DELEGATIONS = {"polyak_update", "RingBuffer", "mean_node_distance", "critic_loss", "adam_step"}


def attacked_submission(folder: Path, canary: Path) -> None:
    folder.mkdir(parents=True)
    for path in notebooks.notebooks_in(SOLUTIONS):
        nb = notebooks.read_notebook(path)
        for cell in nb["cells"]:
            info = notebooks.exercise_info(cell)
            if info and info["exercise"] in ATTACKS:
                first = notebooks.cell_source(cell).split("\n", 1)[0]
                body = ATTACKS[info["exercise"]][1].replace("{canary}", str(canary)) \
                    .replace("{solutions}", str(SOLUTIONS)).replace("{grading}", str(GRADING))
                cell["source"] = (first + body).splitlines(keepends=True)
        notebooks.write_notebook(nb, folder / path.name)


def grade_attacked(root: Path, pendulum_actor: Path) -> dict:
    """Grade a student whose cells attack the grader (in ``root``); the report, with the
    grader's output and the canary that no attack may write."""
    canary = root / "outside" / "canary.txt"
    canary.parent.mkdir(parents=True)
    attacked_submission(root / "student", canary)
    # A genuine hand-in of lesson 13 (an agent that learned: the shipped 2-node actor, graded
    # in an installation that does not ship it), so that own_agent_report, graded from files
    # rather than a cell, must keep its points whatever the other cells attack.
    import shutil

    from dlo_course.paths import AGENTS_DIR, DATA_DIR
    from dlo_course.submission import SUBMISSION_DIR, write_submission

    run = root / "run"
    run.mkdir()
    for name in ("actor.pt", "config.json", "progress.csv"):
        shutil.copyfile(AGENTS_DIR / "nodes2" / name, run / name)
    write_submission(run, root / "student" / SUBMISSION_DIR)
    data = root / "installation" / "data"
    shutil.copytree(DATA_DIR, data, ignore=shutil.ignore_patterns("nodes2"))
    # Likewise lesson 04's Pendulum actor, graded from its file (pendulum_agent): trained by
    # lesson 04's training with the library's pieces (tests/conftest.py).
    from dlo_course.pendulum import ACTOR_FILE

    shutil.copyfile(pendulum_actor, root / "student" / ACTOR_FILE)
    out = root / "grades.json"
    env = dict(os.environ, DLO_COURSE_GRADING_TIMEOUT="8", DLO_COURSE_GRADING_MEMORY_MB="1024",
               DLO_COURSE_DATA=str(data))
    proc = subprocess.run(grading_command(root / "student", json_out=out), cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=900)
    assert out.is_file(), f"no grades written\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    report = json.loads(out.read_text())
    report["output"] = proc.stdout + proc.stderr
    report["canary"] = str(canary)
    return report


@pytest.fixture(scope="session")
def attacked(tmp_path_factory, request):
    """The attacked student's grades, made once for the whole run: under pytest-xdist every
    worker that runs one of these tests would grade it again (70 s each; the loadgroup
    scheduler does not keep this module's tests together with pytest 9), so the workers
    share it through a file under their common temporary folder, behind a lock."""
    from filelock import FileLock  # a dependency of torch

    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent  # one folder per worker, under the run's folder
    kept = shared / "attacked_grades.json"
    with FileLock(str(kept) + ".lock"):
        if kept.is_file():
            report = json.loads(kept.read_text())
        else:
            report = grade_attacked(shared / "attacks",
                                    request.getfixturevalue("trained_pendulum_actor"))
            kept.write_text(json.dumps(report))
    report["canary"] = Path(report["canary"])
    return report


def test_every_attack_scores_zero_and_changes_no_other_verdict(attacked):
    catalog = {e["exercise"]: e["points"] for e in notebooks.exercises(SOLUTIONS)}
    earned = {e["exercise"]: e["earned"] for e in attacked["exercises"]}
    assert set(earned) == set(catalog)
    wrong = {name: earned[name] for name in ATTACKS if earned[name] != 0}
    assert not wrong, f"attacks that scored: {wrong}\n{attacked['output'][-6000:]}"
    # An untouched exercise keeps its points; an untouched prose answer keeps them pending,
    # for the instructor's review (issue 51), earning none automatically.
    got = {e["exercise"]: e["earned"] + e.get("pending", 0) for e in attacked["exercises"]}
    others = {name: (got[name], points) for name, points in catalog.items()
              if name not in ATTACKS and got[name] != points}
    assert not others, f"exercises hurt by another's attack: {others}\n" \
                       f"{attacked['output'][-6000:]}"
    assert attacked["total"] + attacked.get("pending", 0) == \
        sum(p for n, p in catalog.items() if n not in ATTACKS)


def test_attacks_leave_nothing_outside_the_scratch_folder(attacked):
    assert not attacked["canary"].exists(), attacked["canary"].read_text()
    assert not list(attacked["canary"].parent.iterdir())


def test_attack_outcomes_say_why(attacked):
    outcome = {e["exercise"]: e["outcome"] for e in attacked["exercises"]}
    for name in DELEGATIONS:
        assert outcome[name] == "delegates", (name, outcome[name])
    assert outcome["Critic"] == "timeout"
    assert "the answer calls dlo_course.simulation.lame_parameters" in attacked["output"]
    assert "library reference" in attacked["output"]
    if "dlo_course" not in str(REPO):  # else its paths name the library: rejected statically
        assert outcome["ddpg_update"] == "failed"  # it ran, without the solution it tried to read


TRY_ACTION = '''
    try:
        actions[what]()
    except BaseException as err:
        return type(err).__name__
    return None
'''  # the end of a probe that tries one of its ``actions``: the error's name, or None


def run_actions(probes: Path, probe: str, actions) -> dict:
    """``probe(exercise, what)`` of the file ``probes`` in the sandbox, for each ``what`` of
    ``actions``: ``{what: the name of the error it raised, or None}``."""
    sandbox = Sandbox(timeout=20)
    try:
        notebook = SOLUTIONS / "01_rl_and_the_bellman_equation.ipynb"
        results = {what: sandbox.run(notebook, "discounted_return", probes, probe, (what,))
                   for what in actions}
    finally:
        sandbox.close()
    assert all(r["status"] == "ok" for r in results.values()), results
    return {what: r["value"] for what, r in results.items()}


@pytest.mark.parametrize("landlock", ["1", "0"], ids=["landlock-if-any", "audit-hook-only"])
def test_the_sandbox_refuses_writes_signals_and_processes(tmp_path, monkeypatch, landlock):
    """The sandbox on its own, with probes written for the occasion; with Linux Landlock
    where the kernel has it, and with the audit hook alone (what older kernels get)."""
    monkeypatch.setenv("DLO_COURSE_SANDBOX_LANDLOCK", landlock)
    probes = tmp_path / "probes.py"
    canary = tmp_path / "canary.txt"
    probes.write_text(f'''
import os, signal, subprocess, sys
def attempt(fn, what):
    actions = {{
        "write": lambda: open({str(canary)!r}, "w").write("x"),
        "append_repo": lambda: open({str(REPO / "tests" / "grading" / "conftest.py")!r}, "a"),
        "chdir_write": lambda: (os.chdir("/"), open({str(canary)!r}, "w")),
        "relative_escape": lambda: open("../../" + {str(canary)!r}.lstrip("/"), "w"),
        "kill_parent": lambda: os.kill(os.getppid(), signal.SIGKILL),
        "subprocess": lambda: subprocess.run(["true"]),
        "rlimit": lambda: __import__("resource").setrlimit(
            __import__("resource").RLIMIT_AS, (-1, -1)),
        "gc": lambda: __import__("gc").get_objects(),
        "scratch_write": lambda: open("inside.txt", "w").write("fine"),
        "torch_save": lambda: __import__("torch").save([1], {str(canary)!r}),
        "dir_fd": lambda: os.open("canary.txt", os.O_WRONLY | os.O_CREAT,
                                  dir_fd=os.open({str(tmp_path)!r}, os.O_RDONLY)),
        "symlink": lambda: os.symlink({str(canary)!r}, "link.txt"),
        # a fresh interpreter would have no audit hook: seccomp forbids new processes
        "spawn": lambda: __import__("multiprocessing").get_context("spawn").Process(
            target=os.system, args=("echo pwned > " + {str(canary)!r},)).start(),
    }}
''' + TRY_ACTION)
    refused = run_actions(probes, "attempt", (
        "write", "append_repo", "chdir_write", "relative_escape", "kill_parent", "subprocess",
        "rlimit", "gc", "scratch_write", "torch_save", "dir_fd", "symlink", "spawn"))
    assert refused.pop("scratch_write") is None  # its own folder is writable
    assert all(refused.values()), f"not refused: {refused}"
    assert not canary.exists()


READS = {  # what a probe tries to read -> refused (True) or allowed (False)
    "open_solution": True, "pathlib_answers": True, "os_open_answers": True,
    "import_answers": True, "import_from_file": True, "numpy_answers": True,
    "list_solutions": True, "relative_escape": True, "proc_root": True,
    "library": False, "data": False, "stdlib_import": False, "scratch": False, "probe": False}


@pytest.mark.parametrize("landlock", ["1", "0"], ids=["landlock-if-any", "audit-hook-only"])
def test_the_sandbox_refuses_reads_of_the_solutions_and_answers(tmp_path, monkeypatch,
                                                                 landlock):
    """The worker reads Python, the library, its data, the probe's file and its scratch
    folder, nothing else: not solutions/, not tests/grading/answers.py (by open, pathlib,
    os.open, NumPy or an import); with Landlock where the kernel has it, and with the
    audit hook alone."""
    monkeypatch.setenv("DLO_COURSE_SANDBOX_LANDLOCK", landlock)
    probes = tmp_path / "probes.py"
    solution = SOLUTIONS / "04_ddpg.ipynb"
    answers = GRADING / "answers.py"
    probes.write_text(f'''
import importlib.util, os, pathlib, sys
import numpy as np
def read(fn, what):
    def import_from_file():
        spec = importlib.util.spec_from_file_location("leak", {str(answers)!r})
        spec.loader.exec_module(importlib.util.module_from_spec(spec))
    def import_answers():
        sys.path.insert(0, {str(GRADING)!r})
        import answers
    actions = {{
        "open_solution": lambda: open({str(solution)!r}).read(),
        "pathlib_answers": lambda: pathlib.Path({str(answers)!r}).read_text(),
        "os_open_answers": lambda: os.read(os.open({str(answers)!r}, os.O_RDONLY), 100),
        "import_answers": import_answers,
        "import_from_file": import_from_file,
        "numpy_answers": lambda: np.fromfile({str(answers)!r}, dtype=np.uint8),
        "list_solutions": lambda: os.listdir({str(SOLUTIONS)!r}),
        "relative_escape": lambda: open("../" * 40 + {str(answers)!r}.lstrip("/")).read(),
        "proc_root": lambda: open("/proc/self/root" + {str(answers)!r}).read(),
        "library": lambda: open({str(REPO / "dlo_course" / "ddpg.py")!r}).read(),
        "data": lambda: os.listdir({str(DATA_DIR)!r}),
        "stdlib_import": lambda: __import__("colorsys").rgb_to_hsv(1, 0, 0),
        "scratch": lambda: (open("inside.txt", "w").write("x"), open("inside.txt").read()),
        "probe": lambda: open(__file__).read(),
    }}
''' + TRY_ACTION)
    refused = run_actions(probes, "read", READS)
    assert {what: bool(error) for what, error in refused.items()} == READS, refused


def test_data_from_the_sandbox_cannot_carry_code():
    with pytest.raises(DataError):
        encode_data(object())
    with pytest.raises(DataError):
        decode_data({"__ndarray__": ["|O", [1], ""]})
    value = {"a": (1, 2.5, None, "x"), 3: [True, b"\x00"]}
    assert decode_data(json.loads(json.dumps(encode_data(value)))) == value


# ------------------------------------------------------------ delegation, statically


def exercise_cells(folder: Path):
    for path in notebooks.notebooks_in(folder):
        book = ExerciseNotebook.from_path(path)
        for name, source in book.exercise_sources.items():
            yield book, name, source


# Exercises graded from a file the cell writes, not from its code: the grader never loads the
# cell (no delegation check), and pendulum_agent's solution calls the library's training loop
# with the student's own pieces (lesson 04, section 6).
GRADED_FROM_FILES = {"pendulum_agent"}


def test_no_solution_is_taken_for_a_delegation():
    for book, name, source in exercise_cells(SOLUTIONS):
        if name not in GRADED_FROM_FILES:
            assert delegation_problems(source, book.setup_sources) == [], name
    from dlo_course.grading.notebooks import exercises

    graded = {e["exercise"] for e in exercises(SOLUTIONS)}
    assert GRADED_FROM_FILES <= graded


SETUP = "import numpy as np\nfrom dlo_course import ddpg\nfrom dlo_course.replay_buffer import " \
        "ReplayBuffer\nimport dlo_course\nfrom dlo_course.notebook import fast_mode\n"


@pytest.mark.parametrize("cell, why", [
    ("def f(t, s, tau):\n    return ddpg.polyak_update(t, s, tau)", "uses dlo_course.ddpg.polyak_update"),
    ("class RingBuffer(ReplayBuffer):\n    pass", "uses dlo_course.replay_buffer.ReplayBuffer"),
    ("from dlo_course.ddpg import critic_loss as f", "imports from dlo_course.ddpg"),
    ("import dlo_course.ddpg as d\ndef f(q, t):\n    return d.critic_loss(q, t)", "imports dlo_course.ddpg"),
    ("def f(q, t):\n    return getattr(ddpg, 'critic_' + 'loss')(q, t)", "uses getattr on the library"),
    ("import importlib\ndef f(x):\n    return importlib.import_module('m').g(x)", "imports importlib"),
    ("def f(x):\n    return __import__('m').g(x)", "uses __import__"),
    ("import sys\ndef f(x):\n    return sys.modules['m'].g(x)", "uses sys.modules"),
    ("def f(x):\n    return globals()['ReplayBuffer']", "uses globals()"),
    ("def f(x):\n    return eval('x')", "uses eval"),
    ("def f(x):\n    return dlo_course.env.mean_node_distance(x, x)", "uses dlo_course.env.mean_node_distance"),
    ("def f(x):\n    m = 'dlo_course.env'\n    return m", "names the library in a string"),
    ("from dlo_course.grading.bundle import answer_result",  # it reads the grader's answers
     "imports from dlo_course.grading.bundle"),
])
def test_delegation_is_rejected_with_a_reason(cell, why):
    problems = delegation_problems(cell, [SETUP])
    assert any(why in p for p in problems), problems
    message = delegation_message("f", problems)
    assert why in message and "write the code yourself" in message


def test_own_work_and_the_course_helpers_are_accepted():
    for cell in ["def f(x):\n    return np.sum(x) if fast_mode() else 0",
                 "class RingBuffer:\n    def get(self, name):\n        return getattr(self, name)",
                 "import math\ndef f(x):\n    return math.ceil(x)"]:
        assert delegation_problems(cell, [SETUP]) == [], cell
    adam = "def adam_step(p):\n    return torch.optim.Adam([p])"
    assert delegation_problems(adam, [SETUP], ["torch.optim.Adam.step"]) == \
        ["uses torch.optim.Adam"]
