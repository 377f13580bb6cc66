"""The course's notebooks: release, grading, and every solution executed end to end.

The grader itself (tests/grading) is only collected when targeted; here it runs as a
subprocess, on the solutions (everything passes) and on the released lessons (everything
fails), and on made-up student submissions through ``dlo-course course grade``.
"""

from __future__ import annotations

import copy
import csv
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlo_course.cli import main
from dlo_course.grading import bundle as bundle_module
from dlo_course.grading import notebooks
from dlo_course.grading.bundle import STUDENT_EXCLUDE, release_student
from dlo_course.grading.grade import PENDING, grade, grading_command
from dlo_course.paths import AGENTS_DIR
from dlo_course.submission import CSV_COLUMNS
from user_env import use_user_environment

REPO = Path(__file__).resolve().parents[1]
SOLUTIONS, LESSONS = REPO / "solutions", REPO / "lessons"
NOTEBOOKS = notebooks.notebooks_in(SOLUTIONS)


def run_grader(notebooks: Path, tmp_path: Path, timeout_per_exercise: float = 60) -> dict:
    out = tmp_path / f"grades_{notebooks.name}.json"
    env = dict(os.environ, DLO_COURSE_GRADING_TIMEOUT=str(timeout_per_exercise))
    proc = subprocess.run(grading_command(notebooks, json_out=out), cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=600)
    assert out.is_file(), f"no grades written\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    report = json.loads(out.read_text())
    report["returncode"], report["output"] = proc.returncode, proc.stdout + proc.stderr
    return report


@pytest.fixture
def handed_in(trained_hand_in, trained_pendulum_actor, data_without_the_2_node_agent,
              monkeypatch) -> Path:
    """Lesson 13's hand-in folder of an agent that learned, with lesson 04's Pendulum actor
    beside it (tests/conftest.py), graded in an installation that does not ship the 2-node
    agent, so that both earn their points; copy them beside the notebooks to grade them
    (:func:`hand_in`)."""
    from dlo_course.pendulum import ACTOR_FILE

    monkeypatch.setenv("DLO_COURSE_DATA", str(data_without_the_2_node_agent))
    folder = trained_hand_in[0]
    shutil.copyfile(trained_pendulum_actor, folder.parent / ACTOR_FILE)
    return folder


def hand_in(handed_in: Path, folder: Path) -> None:
    """Lesson 13's hand-in folder and lesson 04's Pendulum actor, into ``folder``."""
    from dlo_course.pendulum import ACTOR_FILE

    shutil.copytree(handed_in, folder / handed_in.name)
    shutil.copyfile(handed_in.parent / ACTOR_FILE, folder / ACTOR_FILE)


def report_of(handed_in: Path) -> dict:
    return json.loads((handed_in / "report.json").read_text())


def handed_in_run(handed_in: Path) -> tuple[int, int]:
    """(transitions, episodes) of the run that the hand-in's report records."""
    run = report_of(handed_in)["run"]
    return run["transitions"], run["episodes"]


def catalog() -> dict[str, int]:
    return {e["exercise"]: e["points"] for e in notebooks.exercises(SOLUTIONS)}


def written() -> set[str]:
    """The course's written answers in prose: no pattern gives their points, they await the
    instructor's review (issue 51; a choice among stated options is graded automatically)."""
    return {e["exercise"] for e in notebooks.exercises(SOLUTIONS)
            if e["kind"] == "text" and not e.get("choices")}


# ------------------------------------------------------------------ the course's shape


def test_course_has_enough_lessons_and_exercises():
    assert len(NOTEBOOKS) >= 10
    assert len(catalog()) >= 20
    for required in ("bellman_target", "critic_loss", "ddpg_update", "polyak_update",
                     "mean_node_distance", "reduce_gradients"):
        assert required in catalog()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_each_lesson_has_goals_exercises_summary_and_reading(path):
    nb = notebooks.read_notebook(path)
    markdown = [notebooks.cell_source(c) for c in nb["cells"] if c["cell_type"] == "markdown"]
    text = "\n".join(markdown)
    assert markdown[0].startswith("# Lesson"), "a lesson starts with its title"
    assert "Learning goals" in markdown[0]
    assert "## Summary" in text and "## Further reading" in text
    setup = [c for c in nb["cells"] if notebooks.is_setup(c)]
    exercises = [c for c in nb["cells"] if notebooks.exercise_info(c)]
    assert setup and exercises
    for cell in exercises:  # metadata and the visible first-line comment agree
        info = notebooks.exercise_info(cell)
        first = notebooks.cell_source(cell).split("\n", 1)[0]
        assert first.startswith(f"# exercise: {info['exercise']} ({info['points']} point")
    for cell in nb["cells"]:  # a written answer's metadata and its first-line comment agree
        info = notebooks.answer_info(cell)
        if info is not None:
            # the rubric and a choice's options live in the metadata only
            without_metadata = {**cell, "metadata": {}}
            assert notebooks.answer_info(without_metadata) == \
                {k: v for k, v in info.items() if k not in ("rubric", "choices")}, \
                notebooks.cell_source(cell)


# ------------------------------------------------------------------------ release


def test_lessons_are_exactly_what_release_generates(tmp_path):
    """Drift test: lessons/ must be regenerated (`dlo-course course release`) after any edit
    of solutions/."""
    assert notebooks.release(SOLUTIONS, LESSONS, check=True) == []
    written = notebooks.release(SOLUTIONS, tmp_path)
    assert written == [p.name for p in NOTEBOOKS]
    for name in written:
        assert (tmp_path / name).read_bytes() == (LESSONS / name).read_bytes()
    result = CliRunner().invoke(main, ["course", "release", "--check"])
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("folder", [SOLUTIONS, LESSONS], ids=["solutions", "lessons"])
def test_notebooks_are_committed_without_outputs(folder):
    for path in notebooks.notebooks_in(folder):
        nb = notebooks.read_notebook(path)
        assert not notebooks.has_outputs(nb), f"{path.name} has outputs: clear them before committing"
        assert path.read_text(encoding="utf-8") == notebooks.notebook_json(nb), \
            f"{path.name} is not in Jupyter's JSON layout"


@pytest.mark.parametrize("folder", [SOLUTIONS, LESSONS], ids=["solutions", "lessons"])
def test_notebooks_are_valid_nbformat(folder):
    nbformat = pytest.importorskip("nbformat")
    for path in notebooks.notebooks_in(folder):
        nbformat.validate(nbformat.read(path, as_version=4))


def test_lessons_contain_no_solutions():
    for path in notebooks.notebooks_in(LESSONS):
        for cell in notebooks.read_notebook(path)["cells"]:
            source = notebooks.cell_source(cell)
            assert notebooks.SOLUTION_BEGIN not in source and notebooks.SOLUTION_END not in source
            if notebooks.exercise_info(cell):
                assert "raise NotImplementedError()" in source


def test_strip_solutions_keeps_signature_docstring_and_indentation():
    source = (
        'def f(x):\n'
        '    """Doc."""\n'
        '    ### BEGIN SOLUTION\n'
        '    y = x + 1\n'
        '    return y\n'
        '    ### END SOLUTION\n'
        '\n'
        'class C:\n'
        '    def g(self):\n'
        '        ### BEGIN SOLUTION\n'
        '        return 2\n'
        '        ### END SOLUTION')
    stripped = notebooks.strip_solutions(source)
    assert stripped == (
        'def f(x):\n'
        '    """Doc."""\n'
        '    # YOUR CODE HERE\n'
        '    raise NotImplementedError()\n'
        '\n'
        'class C:\n'
        '    def g(self):\n'
        '        # YOUR CODE HERE\n'
        '        raise NotImplementedError()')
    compile(stripped, "<stripped>", "exec")
    for broken in ("### BEGIN SOLUTION\nx", "### END SOLUTION", "### BEGIN SOLUTION\n"
                   "### BEGIN SOLUTION\n### END SOLUTION"):
        with pytest.raises(ValueError):
            notebooks.strip_solutions(broken)


def test_release_rejects_a_malformed_exercise(tmp_path):
    nb = notebooks.read_notebook(NOTEBOOKS[0])
    cell = next(c for c in nb["cells"] if notebooks.exercise_info(c))
    cell["source"] = [line for line in cell["source"] if "SOLUTION" not in line]
    notebooks.write_notebook(nb, tmp_path / "solutions" / NOTEBOOKS[0].name)
    with pytest.raises(ValueError, match="no solution block"):
        notebooks.release(tmp_path / "solutions", tmp_path / "lessons")


# ------------------------------------------------------------------------ grading


def test_grader_gives_full_points_to_the_solutions(tmp_path, handed_in):
    graded = tmp_path / "solutions"  # a copy, with lesson 13's hand-in (never committed)
    graded.mkdir()
    for path in NOTEBOOKS:
        shutil.copyfile(path, graded / path.name)
    hand_in(handed_in, graded)
    report = run_grader(graded, tmp_path)
    assert report["returncode"] == 0, report["output"][-5000:]
    graded = {e["exercise"]: e for e in report["exercises"]}
    assert {name: e["points"] for name, e in graded.items()} == catalog(), \
        "every exercise needs a grading test, with the points of its notebook metadata"
    failed = [name for name, e in graded.items() if e["outcome"] != "passed"
              and name not in written()]
    assert not failed, report["output"][-5000:]
    # the solutions' notes are written answers like any other: the instructor's to review
    awaiting = {name for name, e in graded.items() if e["outcome"] == "awaiting review"
                and e["earned"] == 0 and e["pending"] == e["points"]}
    assert awaiting == written(), report["output"][-5000:]
    pending = sum(catalog()[name] for name in written())
    assert report["pending"] == pending
    assert report["total"] == report["max_total"] - pending == sum(catalog().values()) - pending
    assert "TOTAL" in report["output"] and "await the instructor's review" in report["output"]


def test_grader_fails_every_exercise_of_the_untouched_lessons(tmp_path):
    report = run_grader(LESSONS, tmp_path)
    assert report["returncode"] != 0
    assert {e["exercise"] for e in report["exercises"]} == set(catalog())
    passed = [e["exercise"] for e in report["exercises"] if e["outcome"] == "passed"]
    assert not passed, f"these exercises pass without an answer: {passed}"
    assert report["total"] == 0


SUBMITTED_LESSONS = ("01_", "02_", "04_", "05_", "13_")
"""The lessons alice and bob hand in to `course grade`: those where bob goes wrong (a full
course for each costs 100 s more; test_grader_gives_full_points_to_the_solutions grades it
all)."""


def make_submissions(root: Path, handed_in: Path) -> None:
    """alice: the solutions of SUBMITTED_LESSONS and lesson 13's hand-in. bob: the same
    lessons but 2 (a missing notebook), no hand-in, one endless loop, one syntax error, an
    exercise cell that lost its metadata (kept its comment), a crashing answer."""
    alice, bob = root / "alice", root / "bob"
    alice.mkdir(parents=True)
    bob.mkdir(parents=True)
    hand_in(handed_in, alice)
    for path in NOTEBOOKS:
        if not path.stem.startswith(SUBMITTED_LESSONS):
            continue
        (alice / path.name).write_bytes(path.read_bytes())
        if path.stem.startswith("02_"):
            continue  # bob did not hand in lesson 2
        nb = notebooks.read_notebook(path)
        for cell in nb["cells"]:
            info = notebooks.exercise_info(cell)
            if info is None:
                continue
            source = notebooks.cell_source(cell)
            if info["exercise"] == "bellman_target":
                source = source.replace("### BEGIN SOLUTION", "while True:\n        pass")
            elif info["exercise"] == "discounted_return":
                source = source + "\n    def (broken syntax\n"
            elif info["exercise"] == "lame_parameters":
                cell["metadata"].pop(notebooks.METADATA_KEY)  # only the comment is left
            elif info["exercise"] == "critic_loss":
                source = source.replace("### BEGIN SOLUTION", "return 1 / 0")
            cell["source"] = source.splitlines(keepends=True)
        notebooks.write_notebook(nb, bob / path.name)


def test_grade_command_grades_each_student_and_isolates_failures(tmp_path, monkeypatch,
                                                                 handed_in):
    make_submissions(tmp_path / "submissions", handed_in)
    # bob's endless loop waits out the limit. 15 s: at 5 s alice's correct answers lost 2
    # points on a loaded machine (twice in a row), and the slowest (ddpg_update, td3_update)
    # take 3-4 s alone.
    monkeypatch.setenv("DLO_COURSE_GRADING_TIMEOUT", "15")
    out = tmp_path / "grades.csv"
    result = CliRunner().invoke(main, ["course", "grade", str(tmp_path / "submissions"),
                                       "--out", str(out), "--leaderboard",
                                       str(tmp_path / "agents.md")])
    assert result.exit_code == 0, result.output
    board = (tmp_path / "agents.md").read_text().splitlines()  # alice's hand-in, verified
    table = [[cell.strip() for cell in line.strip().strip("|").split("|")]
             for line in board if line.startswith(("| 1 ", "| 2 "))]
    assert [cells[1:3] for cells in table] == [["alice", "yes"], ["bob", "no"]]
    assert table[0][6:] == ["yes", f"{report_of(handed_in)['done_percent']:g}",
                            *(str(v) for v in handed_in_run(handed_in))]
    assert table[1][3:] == [""] * 7
    with out.open(newline="") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    points = catalog()
    handed = {e["exercise"] for e in notebooks.exercises(SOLUTIONS)
              if e["notebook"].startswith(SUBMITTED_LESSONS)}
    assert list(rows) == ["alice", "bob"]
    alice = rows["alice"]
    def got(row, name):  # a written answer handed in awaits review
        return row[name] if row[name] == PENDING else float(row[name])

    for name, value in points.items():
        expected = (PENDING if name in written() else value) if name in handed else 0
        assert got(alice, name) == expected, f"alice's {name}"
    assert float(alice["max_total"]) == sum(points.values())
    assert float(alice["total"]) == sum(points[n] for n in handed - written())
    assert float(alice["pending"]) == sum(points[n] for n in handed & written())
    assert set(alice["awaiting_review"].split()) == handed & written()
    bob = rows["bob"]
    lost = {"bellman_target", "discounted_return", "critic_loss", "RingBuffer", "prediction_ring",
            "own_agent_report", "pendulum_agent"} | (set(points) - handed)
    for name, value in points.items():
        expected = 0 if name in lost else PENDING if name in written() else value
        assert got(bob, name) == expected, f"bob's {name}: {bob[name]}, expected {expected}"
    assert float(bob["total"]) == sum(points.values()) - sum(points[n] for n in lost | written())


def test_written_answers_are_released_as_placeholders():
    """A written answer's cell keeps its first-line comment; the instructor's notes go."""
    found = 0
    for path in NOTEBOOKS:
        solution = notebooks.read_notebook(path)
        lesson = notebooks.read_notebook(LESSONS / path.name)
        for mine, theirs in zip(solution["cells"], lesson["cells"], strict=True):
            info = notebooks.answer_info(mine)
            if info is None:
                continue
            found += 1
            assert notebooks.answer_info(theirs) == info
            assert notebooks.answer_text(theirs) == ""
            assert notebooks.ANSWER_PLACEHOLDER in notebooks.cell_source(theirs)
            assert notebooks.written_answer_problem(notebooks.answer_text(mine),
                                                 info["min_words"]) is None, \
                f"{path.name}: the solution's {info['exercise']} is too short for its own grader"
    assert found >= 2


def test_written_answer_problem_counts_words():
    assert notebooks.written_answer_problem("", 3).startswith("no answer written")
    assert notebooks.written_answer_problem("  \n ", 1).startswith("no answer written")
    assert "2 words" in notebooks.written_answer_problem("Two words.", 3)
    assert notebooks.written_answer_problem("The paper's 4-node agent wins.", 5) is None
    cell = {"cell_type": "markdown", "metadata": {},
            "source": "<!-- answer: guess (1 point, at least 4 words) -->\nYOUR ANSWER HERE"}
    assert notebooks.answer_info(cell) == {"exercise": "guess", "points": 1, "min_words": 4,
                                        "kind": "text"}
    assert notebooks.answer_text(cell) == ""
    cell["source"] += "\nA few of my own words."
    assert notebooks.answer_text(cell) == "A few of my own words."


CAPSTONE = "13_capstone_table_one"


def test_written_answers_go_verbatim_into_the_csv_and_feedback_sheets(tmp_path, handed_in):
    """Grading a class records each written answer verbatim in the CSV (no points of its own:
    awaiting the instructor's review if long enough, 0 if not) and writes one Markdown
    feedback sheet per student: points per exercise and the failing check's message, without
    tracebacks."""
    catalog_dir = tmp_path / "catalog"
    catalog_dir.mkdir()
    (catalog_dir / f"{CAPSTONE}.ipynb").write_bytes((SOLUTIONS / f"{CAPSTONE}.ipynb").read_bytes())
    submissions = tmp_path / "submissions"
    (submissions / "alice").mkdir(parents=True)
    (submissions / "bob").mkdir(parents=True)
    (submissions / "carol").mkdir(parents=True)  # hands in nothing
    (submissions / "alice" / f"{CAPSTONE}.ipynb").write_bytes(
        (SOLUTIONS / f"{CAPSTONE}.ipynb").read_bytes())
    hand_in(handed_in, submissions / "alice")
    essay = ('Our agents trail the paper in most cells, "clearly"; yet, with 20 episodes,\n'
             "the intervals are wide — so: more episodes first, then longer training, on more "
             "ranks, before any claim of a reproduction can be made by anyone.")
    nb = notebooks.read_notebook(LESSONS / f"{CAPSTONE}.ipynb")
    for cell in nb["cells"]:
        info = notebooks.graded_info(cell)
        if info is None:
            continue
        source = notebooks.cell_source(cell)
        if info["exercise"] == "analysis_next_step":
            source = source.replace(notebooks.ANSWER_PLACEHOLDER, essay)
        elif info["exercise"] == "prediction_cells":
            source = source.replace(notebooks.ANSWER_PLACEHOLDER, "Six.")
        cell["source"] = source.splitlines(keepends=True)
    notebooks.write_notebook(nb, submissions / "bob" / f"{CAPSTONE}.ipynb")

    out = tmp_path / "grades.csv"
    rows = grade(submissions, out, notebooks.GRADING_TESTS_DIR / f"test_{CAPSTONE}.py",
                        catalog=catalog_dir, progress=False)
    assert [r["student"] for r in rows] == ["alice", "bob", "carol"]
    with out.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        graded = [e for e in notebooks.exercises(catalog_dir)]
        texts = [e["exercise"] for e in graded if e["kind"] == "text"]
        assert reader.fieldnames == ["student", *[e["exercise"] for e in graded], "total",
                                     "max_total", "pending", "awaiting_review", "error",
                                     *CSV_COLUMNS,
                                     *[f"{t}_{part}" for t in texts
                                                             for part in ("text", "rubric")]]
        csv_rows = {row["student"]: row for row in reader}
    alice, bob, carol = csv_rows["alice"], csv_rows["bob"], csv_rows["carol"]
    points = {e["exercise"]: e["points"] for e in graded}
    assert float(alice["max_total"]) == sum(points.values())
    assert float(alice["total"]) == sum(points.values()) - sum(points[t] for t in texts)
    assert float(alice["pending"]) == sum(points[t] for t in texts)
    assert set(alice["awaiting_review"].split()) == set(texts)
    for name in texts:  # the instructor's notes, as the student's notebook holds them
        assert alice[f"{name}_text"] == notebooks.written_answers(
            SOLUTIONS / f"{CAPSTONE}.ipynb")[name]["text"]
    assert bob["analysis_next_step_text"] == essay  # verbatim: newline, quotes, commas
    assert bob["analysis_next_step"] == PENDING and bob["awaiting_review"] == "analysis_next_step"
    assert bob["prediction_cells_text"] == "Six." and float(bob["prediction_cells"]) == 0
    assert bob["analysis_comparison_text"] == "" and float(bob["analysis_comparison"]) == 0
    # the hand-in: alice's agent, measured by the grader, her report verified; bob's absent
    report = report_of(handed_in)
    assert float(alice["own_agent_report"]) == points["own_agent_report"]
    assert float(alice["measured_done_percent"]) == float(alice["claimed_done_percent"]) \
        == report["done_percent"]
    assert alice["report_verified"] == "1" and float(alice["do_nothing_distance"]) > 0
    progress = (AGENTS_DIR / "nodes2" / "progress.csv").read_text().splitlines()
    last = dict(zip(progress[0].split(","), progress[-1].split(",")))
    assert (alice["claimed_run_transitions"], alice["claimed_run_episodes"]) == (
        last["transitions"], last["episode"])
    assert [bob[c] for c in CSV_COLUMNS] == [""] * len(CSV_COLUMNS)
    assert [carol[c] for c in CSV_COLUMNS] == [""] * len(CSV_COLUMNS)
    assert float(carol["total"]) == 0 and all(carol[f"{t}_text"] == "" for t in texts)

    feedback = tmp_path / "grades_feedback"
    assert sorted(p.name for p in feedback.iterdir()) == ["alice.md", "bob.md", "carol.md"]
    assert "Every check passed." in (feedback / "alice.md").read_text()
    sheet = (feedback / "bob.md").read_text()
    assert f"**Total: {float(bob['total']):g} / {sum(points.values()):g} points.**" in sheet
    assert "### `own_agent_report`" in sheet and "no report.json" in sheet
    assert "1 word: this answer needs at least 10 words" in sheet
    assert "no answer written" in sheet  # analysis_comparison
    for noise in ("Traceback", "tests/grading/", "conftest.py", "Failed: "):
        assert noise not in sheet, noise
    assert f"no notebook {CAPSTONE}.ipynb" in (feedback / "carol.md").read_text()


def test_release_cli_passes_the_grading_tests_folder(tmp_path, monkeypatch):
    """`dlo-course course release --student DIR --tests T` hands T to release_student;
    --tests without --student is refused."""
    seen = {}

    def fake_release_student(dest, **kwargs):
        seen.update(kwargs, dest=dest)
        return ["README.md"]

    monkeypatch.setattr(bundle_module, "release_student", fake_release_student)
    tests = tmp_path / "my_grading"
    tests.mkdir()
    result = CliRunner().invoke(main, ["course", "release", "--student",
                                       str(tmp_path / "bundle"), "--tests", str(tests)])
    assert result.exit_code == 0, result.output
    assert Path(seen["tests"]) == tests and Path(seen["dest"]) == tmp_path / "bundle"
    result = CliRunner().invoke(main, ["course", "release", "--student",
                                       str(tmp_path / "bundle2")])
    assert result.exit_code == 0, result.output
    assert Path(seen["tests"]) == notebooks.GRADING_TESTS_DIR
    refused = CliRunner().invoke(main, ["course", "release", "--check", "--tests", str(tests)])
    assert refused.exit_code != 0 and "--tests" in refused.output


# ---------------------------------------------------------------- running the notebooks


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_solution_notebook_runs_top_to_bottom_on_the_fast_budget(path, tmp_path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    missing = notebooks.missing_data(notebooks.read_notebook(path))
    if missing:
        pytest.skip(f"needs {', '.join(str(m) for m in missing)} (not generated yet)")
    # The kernel starts as a student's does: default torch threads, none of the suite's
    # variables (lessons 09, 10, 13, 14 and 16 fork episodes after loading an agent, which hung
    # with several threads: issue 48), only fast mode and an output folder set.
    use_user_environment(monkeypatch, DLO_COURSE_FAST="1",
                         DLO_COURSE_OUTPUT=str(tmp_path / "output"))
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=240, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    # No wall-time assertion: on a shared machine it failed lesson 09 at 280 s beside two
    # other jobs (2026-12-07). The cell timeout above catches a hang; speed is a benchmark's.
    client.execute()


# Exercises graded from files handed in beside the notebooks, not from their cells
HANDED_IN_ITEMS = ("own_agent_report", "pendulum_agent")

# Exercises whose solution calls earlier answers of its notebook: graded right only with them
USES_EARLIER = {"Critic": ("build_mlp",),
                "sweep_offsets_inside": ("level_moves",),
                "td3_target": ("smoothed_target_action",),
                "td3_update": ("td3_target", "smoothed_target_action"),
                "table_verdict": ("wilson_interval",)}


def class_of(root: Path, n_students: int = 6) -> dict[str, dict[str, float]]:
    """``n_students`` copies of lessons/ with mixed answers (each exercise solved, left
    unsolved or answered wrongly, by a mutant of the mutation suite); one student hands in
    nothing for the last lesson. Returns the points each student should get.

    Student i gives exercise j the answer (7 i + 3 j) mod 4 (unsolved, solved twice, wrong):
    any 4 consecutive students give every exercise all four. An exercise whose answer calls
    earlier ones (USES_EARLIER) is left unsolved by a student who did not get those right,
    and is solved and answered wrongly in turn by those who did: the rotation alone gave
    Critic and td3_update no right answer in the whole class. The test checks that every
    exercise is solved, wrong and unsolved by someone: six students is the fewest that does
    (with four or five, nobody answers td3_update wrongly)."""
    from test_mutations import MUTANTS, mutate

    points = catalog()
    solved = {}
    for path in NOTEBOOKS:
        for cell in notebooks.read_notebook(path)["cells"]:
            info = notebooks.exercise_info(cell)
            if info:
                solved[info["exercise"]] = notebooks.cell_source(cell)
    expected = {}
    turns = {exercise: 0 for exercise in USES_EARLIER}  # right, then wrong, then right...
    for i in range(n_students):
        name = f"student{i:02d}"
        (root / name).mkdir(parents=True)
        expected[name] = {}
        chosen: dict[str, int] = {}
        for path in notebooks.notebooks_in(LESSONS):
            if i == n_students - 1 and path == notebooks.notebooks_in(LESSONS)[-1]:
                expected[name].update({e["exercise"]: 0 for e in notebooks.exercises(SOLUTIONS)
                                       if e["notebook"] == path.stem})
                continue
            nb = notebooks.read_notebook(path)
            for cell in nb["cells"]:
                info = notebooks.exercise_info(cell)
                if info is None:
                    continue
                exercise = info["exercise"]
                j = list(points).index(exercise)
                choice = (7 * i + 3 * j) % 4  # 0: unsolved, 1-2: solved, 3: a wrong answer
                if exercise in USES_EARLIER:
                    if any(chosen.get(d) not in (1, 2) for d in USES_EARLIER[exercise]):
                        choice = 0  # its answer calls one this student did not get right
                    else:
                        choice = (1, 3)[turns[exercise] % 2]
                        turns[exercise] += 1
                chosen[exercise] = choice
                got = 0
                if choice in (1, 2):
                    cell["source"] = solved[exercise].splitlines(keepends=True)
                    # graded from what is handed in beside the notebooks (lesson 13's
                    # folder, lesson 04's Pendulum actor), which no one here hands in
                    got = 0 if exercise in HANDED_IN_ITEMS else points[exercise]
                elif choice == 3:
                    old, new = MUTANTS[exercise][0][1:3]
                    cell["source"] = mutate(solved[exercise], old, new).splitlines(keepends=True)
                expected[name][exercise] = got
                expected[name].setdefault("_answers", {})[exercise] = choice
            notebooks.write_notebook(nb, root / name / path.name)
    answers = {name: points.pop("_answers") for name, points in expected.items()}
    for exercise in answers["student00"]:  # the code exercises (written answers stay empty)
        given = {("unsolved", "solved", "solved", "wrong")[a[exercise]]
                 for a in answers.values() if exercise in a}
        assert given == {"unsolved", "solved", "wrong"}, (exercise, given)
    return expected


def test_grading_a_class_gives_the_right_csv(tmp_path):
    expected = class_of(tmp_path / "submissions")
    out = tmp_path / "grades.csv"
    started = time.perf_counter()
    result = CliRunner().invoke(main, ["course", "grade", str(tmp_path / "submissions"),
                                       "--out", str(out), "--jobs", "2"])
    elapsed = time.perf_counter() - started
    assert result.exit_code == 0, result.output
    texts = [f"{e['exercise']}_{part}" for e in notebooks.exercises(SOLUTIONS)
             if e["kind"] == "text" for part in ("text", "rubric")]
    with out.open(newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == ["student", *catalog(), "total", "max_total", "pending",
                                     "awaiting_review", "error", *CSV_COLUMNS, *texts]
        rows = {row["student"]: row for row in reader}
    assert list(rows) == sorted(expected)
    for student, points in expected.items():
        row = rows[student]
        got = {name: float(row[name]) for name in points}
        assert got == {name: float(p) for name, p in points.items()}, student
        assert float(row["total"]) == sum(points.values())
        assert float(row["max_total"]) == sum(catalog().values())
        assert row["error"] == ""
    print(f"graded {len(expected)} students in {elapsed:.0f} s")


def test_student_bundle_has_no_solutions_and_no_answers(tmp_path):
    bundle = tmp_path / "bundle"
    result = CliRunner().invoke(main, ["course", "release", "--student", str(bundle)])
    assert result.exit_code == 0, result.output
    files = {p.relative_to(bundle).as_posix() for p in bundle.rglob("*") if p.is_file()}
    assert "README.md" in files and "dlo_course/grading/sandbox.py" in files and "pyproject.toml" in files
    for left_out in STUDENT_EXCLUDE:
        if left_out != "lessons/":
            assert not any(f == left_out or f.startswith(left_out) for f in files), left_out
    for path in NOTEBOOKS:
        assert (bundle / "lessons" / path.name).read_bytes() == \
            (LESSONS / path.name).read_bytes()
    for name in files:
        if name.endswith(".ipynb"):
            text = (bundle / name).read_text(encoding="utf-8")
            assert notebooks.SOLUTION_BEGIN not in text
    # the grader stays, for self-grading; no file quotes a solution block's lines
    assert "tests/grading/conftest.py" in files
    answers = set()
    for path in NOTEBOOKS:
        for cell in notebooks.read_notebook(path)["cells"]:
            source = notebooks.cell_source(cell)
            if notebooks.exercise_info(cell) and notebooks.SOLUTION_BEGIN in source:
                block = source.split(notebooks.SOLUTION_BEGIN, 1)[1].split(notebooks.SOLUTION_END)[0]
                answers.add(block.strip())
    for name in files:
        if name.startswith(("tests/", "lessons/")):
            text = (bundle / name).read_text(encoding="utf-8", errors="replace")
            assert not [a for a in answers if a in text], name
    # the grader's own answers stay behind, their probes' results go instead; no grading
    # file defines an answer the library lacks
    assert "tests/grading/answers.py" not in files and "tests/grading/answers.json" in files
    for name in files:
        if name.startswith("tests/grading/") and name.endswith(".py"):
            text = (bundle / name).read_text(encoding="utf-8")
            for leak in ("def reference_discounted_return", "def reference_sweep",
                         "def reference_stored_done", "def library_pack",
                         "q.max(axis=1)[next_state]", "gamma**k * r"):
                assert leak not in text, (name, leak)
    # refuses to write into the repository or over a folder that holds files
    again = CliRunner().invoke(main, ["course", "release", "--student", str(bundle)])
    assert again.exit_code != 0 and "not empty" in again.output
    inside = CliRunner().invoke(main, ["course", "release", "--student", str(REPO / "bundle")])
    assert inside.exit_code != 0 and "outside the repository" in inside.output


def test_students_can_grade_themselves_with_the_bundle(tmp_path):
    """The bundle's grader, without the grader's own answers, gives the solutions full marks
    and an unsolved lesson none, on the exercises whose references were recorded."""
    bundle = tmp_path / "bundle"
    release_student(bundle)
    recorded = json.loads((bundle / "tests" / "grading" / "answers.json").read_text())
    out = tmp_path / "grades.json"
    names = sorted(recorded)
    for folder, expected in ((SOLUTIONS, "all"), (bundle / "lessons", "none")):
        cmd = grading_command(folder, bundle / "tests" / "grading", out) + \
            ["-k", " or ".join(names)]
        proc = subprocess.run(cmd, cwd=bundle, capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, DLO_COURSE_FAST="1"))
        report = json.loads(out.read_text())
        earned = {e["exercise"]: e["earned"] == e["points"] for e in report["exercises"]
                  if e["exercise"] in recorded}  # -k pack_gradients also runs unpack_...
        assert sorted(earned) == names, proc.stdout[-3000:]
        assert all(earned.values()) if expected == "all" else not any(earned.values()), \
            proc.stdout[-3000:]


def test_parallel_grading_gives_the_serial_csv_and_feedback(tmp_path):
    """--jobs only changes how many students are graded at once: the CSV, the logs' verdicts
    and the feedback sheets are those of a serial run (two students, one lesson each: two
    jobs grade both at once)."""
    import shutil

    first = notebooks.notebooks_in(SOLUTIONS)[0].name
    for name, source in (("ann", SOLUTIONS), ("bob", LESSONS)):
        (tmp_path / "class" / name).mkdir(parents=True)
        shutil.copy(source / first, tmp_path / "class" / name / first)
    outputs = {}
    for jobs in (1, 2):
        out = tmp_path / f"jobs{jobs}" / "grades.csv"
        out.parent.mkdir()
        grade(tmp_path / "class", out, progress=False, jobs=jobs)
        sheets = sorted((out.parent / "grades_feedback").iterdir())
        feedback = {p.name: p.read_text() for p in sheets}
        outputs[jobs] = (out.read_text(), feedback)
    assert outputs[1] == outputs[2]
    with (tmp_path / "jobs2" / "grades.csv").open(newline="") as f:
        totals = {row["student"]: float(row["total"]) for row in csv.DictReader(f)}
    assert totals["bob"] == 0 and totals["ann"] > 0


def test_a_class_shares_the_mpi_reference_and_reads_it(tmp_path):
    """`course grade` computes the MPI reference of sum_gradients_over_ranks once for the
    class (two MPI launches, about 10 s a student): the first grader leaves it as plain data,
    the next reads it. Proof that it is read: a tampered reference costs a right answer its
    points."""
    from dlo_course.grading.grade import grade_folder

    lesson = next(p for p in NOTEBOOKS if p.stem.startswith("08_"))
    student = tmp_path / "ann"
    student.mkdir()
    shutil.copy(lesson, student / lesson.name)
    shared = tmp_path / "references"
    shared.mkdir()
    first = grade_folder(student, reference_cache=shared)
    earned = {e["exercise"]: e["earned"] for e in first["exercises"]}
    assert earned["sum_gradients_over_ranks"] == 3, first["output"][-3000:]
    (kept,) = shared.glob("*.json")
    assert len(json.loads(kept.read_text())) == 2  # one result per rank
    kept.write_text("[]")  # no rank's result: a grader that reads it cannot match
    second = grade_folder(student, reference_cache=shared)
    earned = {e["exercise"]: e["earned"] for e in second["exercises"]}
    assert earned["sum_gradients_over_ranks"] == 0
    assert earned["pack_gradients"] == 1  # only the MPI reference is shared
