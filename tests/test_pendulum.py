"""Lesson 04's Pendulum training with the student's pieces (dlo_course.pendulum), and the grade
that depends on what the actor learned.

The pieces are read from the solution notebooks as lesson 04 reads a student's
(``pendulum.earlier_answer``), or from a copy with one mistake of the mutation suite
(``tests/test_mutations.py``). The slow tests train lesson 04's training itself
(``pendulum.TRAIN_STEPS`` steps, seed 0): about 20 s of CPU each, six trainings; the
grader runs in a subprocess, as ``dlo-course grade`` runs it.
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
import torch

from dlo_course import pendulum
from dlo_course.ddpg import Actor, save_network
from dlo_course.grading import notebooks
from dlo_course.grading.grade import grading_command
from dlo_course.paths import REPO_ROOT
from test_mutations import MUTANTS, mutate

SOLUTIONS = REPO_ROOT / "solutions"
LESSON = "04_ddpg"
WHERE = {"RingBuffer": "02_experience_replay", "Critic": "03_actor_and_critic",
         "ddpg_update": LESSON}
KEY = {"RingBuffer": "buffer_class", "Critic": "critic_class", "ddpg_update": "update"}


def solution_pieces(folder=SOLUTIONS) -> dict:
    """The solutions' RingBuffer, Critic and ddpg_update, as train_pendulum takes them."""
    return {KEY[name]: pendulum.earlier_answer(stem, name, folder)
            for name, stem in WHERE.items()}


def mutant_pieces(exercise: str, mistake: str, folder) -> dict:
    """The solutions' pieces but ``exercise``, which carries the mutation suite's
    ``mistake``: its notebook is copied to ``folder`` with that one cell changed."""
    old, new = next(m[1:3] for m in MUTANTS[exercise] if m[0] == mistake)
    stem = WHERE[exercise]
    nb = notebooks.read_notebook(SOLUTIONS / f"{stem}.ipynb")
    for cell in nb["cells"]:
        info = notebooks.exercise_info(cell)
        if info and info["exercise"] == exercise:
            cell["source"] = mutate(notebooks.cell_source(cell), old, new).splitlines(True)
    notebooks.write_notebook(nb, folder / f"{stem}.ipynb")
    pieces = solution_pieces()
    pieces[KEY[exercise]] = pendulum.earlier_answer(stem, exercise, folder)
    return pieces


def graded_return(pieces) -> float:
    torch.set_num_threads(1)
    agent, _ = pendulum.train_pendulum(**pieces)
    return float(np.mean(pendulum.evaluate_actor(agent.actor)))


def test_a_missing_notebook_gives_none_and_a_present_one_the_student_s_class(tmp_path):
    assert pendulum.earlier_answer("02_experience_replay", "RingBuffer", tmp_path) is None
    buffer_class = pendulum.earlier_answer("02_experience_replay", "RingBuffer", SOLUTIONS)
    assert buffer_class.__name__ == "RingBuffer" and buffer_class.__module__ == "__notebook__"


def test_the_solutions_pieces_train_bit_for_bit_as_the_library_s():
    """A short training (100 updates): same returns and same actor weights, so the library's
    training is the reference the solutions match."""
    torch.set_num_threads(1)
    short = dict(steps=600, warmup=500)
    mine, mine_returns = pendulum.train_pendulum(**solution_pieces(), **short)
    library, library_returns = pendulum.train_pendulum(**pendulum.library_pieces(), **short)
    assert mine_returns == library_returns
    for a, b in zip(mine.actor.parameters(), library.actor.parameters(), strict=True):
        assert torch.equal(a, b)
    for a, b in zip(mine.critic_target.parameters(), library.critic_target.parameters(),
                    strict=True):
        assert torch.equal(a, b)


@pytest.mark.slow
def test_the_solutions_pieces_train_past_the_floor_and_earn_the_points(tmp_path):
    """Lesson 04's training with the solutions' pieces, then the grader on its actor."""
    torch.set_num_threads(1)
    agent, _ = pendulum.train_pendulum(**solution_pieces())
    assert np.mean(pendulum.evaluate_actor(agent.actor)) > pendulum.RETURN_FLOOR
    trained = tmp_path / "trained.pt"
    save_network(agent.actor, trained)
    assert grade_pendulum(tmp_path, trained) == 2


# One mistake per piece that the training shows (a wrong done flag does not: Pendulum never
# terminates; the grading tests of lessons 2-4 catch those), and how: the return stays below
# the floor (None), or the training stops with this error (a critic that detaches the action
# leaves the actor's loss without a gradient, and its backward() fails at the first update).
WRONG_PIECES = [("RingBuffer", "samples empty rows", None),
                ("Critic", "action detached: no dQ/da for the actor",
                 "does not require grad"),
                ("Critic", "squeezed output", None),
                ("ddpg_update", "policy loss with the wrong sign", None),
                ("ddpg_update", "Polyak on the actor's target only", None)]


@pytest.mark.slow
@pytest.mark.parametrize("exercise, mistake, error", WRONG_PIECES,
                         ids=[f"{e}-{m.split(':')[0]}" for e, m, _ in WRONG_PIECES])
def test_a_wrong_piece_makes_the_training_fail(exercise, mistake, error, tmp_path):
    pieces = mutant_pieces(exercise, mistake, tmp_path)
    if error is None:
        assert graded_return(pieces) < pendulum.RETURN_FLOOR
    else:
        with pytest.raises(RuntimeError, match=error):
            graded_return(pieces)


# ------------------------------------------------------------------ the grade


def grade_pendulum(tmp_path, actor_file) -> float:
    """Lesson 04's pendulum_agent points for the solution notebook handed in with
    ``actor_file`` (or none), by the real grader."""
    student = tmp_path / "student"
    student.mkdir()
    shutil.copyfile(SOLUTIONS / f"{LESSON}.ipynb", student / f"{LESSON}.ipynb")
    if actor_file is not None:
        shutil.copyfile(actor_file, student / pendulum.ACTOR_FILE)
    out = tmp_path / "grades.json"
    tests = notebooks.GRADING_TESTS_DIR / f"test_{LESSON}.py"
    command = grading_command(student, tests, json_out=out) + ["-k", "pendulum_agent"]
    proc = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, timeout=600)
    assert out.is_file(), f"no grades written\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    earned = {e["exercise"]: e["earned"] for e in json.loads(out.read_text())["exercises"]}
    return earned["pendulum_agent"]


def test_the_grader_gives_nothing_to_an_actor_that_did_not_learn(tmp_path):
    torch.manual_seed(0)
    untrained = tmp_path / "untrained.pt"
    save_network(Actor(3, 1, -2.0, 2.0, pendulum.PENDULUM_DDPG.hidden_sizes), untrained)
    result = pendulum.evaluate_actor_file(untrained)
    assert result["mean_return"] < pendulum.RETURN_FLOOR and not result["passed"]
    assert grade_pendulum(tmp_path, untrained) == 0


def test_the_grader_gives_nothing_without_an_actor_file(tmp_path):
    assert grade_pendulum(tmp_path, None) == 0
