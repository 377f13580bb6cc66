"""Colab and Binder: the lessons' install cell, the badges, and ``binder/``. Nothing here
reaches the network: Colab is recognised by a module name, which the tests fake."""

from __future__ import annotations

import importlib.util
import os
import sys
import types

import pytest

from dlo_course import notebook
from dlo_course.grading import notebooks
from dlo_course.paths import REPO_ROOT

NOTEBOOKS = notebooks.notebooks_in(REPO_ROOT / "solutions")


def load_update_links():
    spec = importlib.util.spec_from_file_location("update_links",
                                                  REPO_ROOT / "binder" / "update_links.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def in_colab(monkeypatch):
    monkeypatch.setitem(sys.modules, "google.colab", types.ModuleType("google.colab"))


def test_no_install_command_outside_colab(monkeypatch):
    monkeypatch.delitem(sys.modules, "google.colab", raising=False)
    assert notebook.colab_install_command() is None


def test_in_colab_the_command_clones_and_installs_without_the_torch_pin(in_colab):
    command = notebook.colab_install_command()
    assert command is not None
    assert f"git clone --quiet --depth 1 --branch main {notebook.REPOSITORY_URL} " \
           f"{notebook.COLAB_CHECKOUT}" in command
    assert f"pip install --quiet -e '{notebook.COLAB_CHECKOUT}[mpi]'" in command
    # Colab's own torch stays: no constraints file, no torch index, no notebooks extra.
    for absent in ("constraints", "torch", "notebooks"):
        assert absent not in command
    # A second run of the cell keeps the clone instead of failing on it.
    assert command.startswith(f"( [ -d {notebook.COLAB_CHECKOUT} ] || git clone")


def run_cell(monkeypatch) -> list[str]:
    """Execute the install cell with ``subprocess.run`` replaced; the commands it ran."""
    import subprocess

    ran = []
    monkeypatch.setattr(subprocess, "run", lambda command, **kw: ran.append(command))
    monkeypatch.setattr(sys, "path", list(sys.path))  # the cell may add to it
    exec(compile(notebook.install_cell_source(), "install-cell", "exec"), {})
    return ran


def test_the_cell_runs_the_command_in_colab_and_makes_the_clone_importable(in_colab,
                                                                             monkeypatch):
    assert run_cell(monkeypatch) == [notebook.colab_install_command()]
    assert sys.path[0] == notebook.COLAB_CHECKOUT


def test_the_cell_does_nothing_elsewhere(monkeypatch):
    monkeypatch.delitem(sys.modules, "google.colab", raising=False)
    before = list(sys.path)
    assert run_cell(monkeypatch) == []
    assert sys.path == before


@pytest.mark.parametrize("folder", ["solutions", "lessons"])
def test_every_lesson_starts_with_the_install_cell(folder):
    """The first code cell, right after the title: up to date with the helper (else run
    `python binder/update_links.py && dlo-course course release`)."""
    for path in notebooks.notebooks_in(REPO_ROOT / folder):
        cells = notebooks.read_notebook(path)["cells"]
        code = [c for c in cells if c["cell_type"] == "code"]
        assert cells[1] is code[0], path.name
        assert notebooks.cell_source(code[0]) == notebook.install_cell_source(), path.name
        assert code[0]["id"] == f"{path.name[:2]}-colab"


def test_lesson_8_says_what_to_do_when_mpiexec_fails_in_colab():
    path = REPO_ROOT / "lessons" / "08_learning_parallelisation_with_mpi.ipynb"
    cells = notebooks.read_notebook(path)["cells"]
    k = next(i for i, c in enumerate(cells) if "run_two_ranks(" in notebooks.cell_source(c))
    note = notebooks.cell_source(cells[k - 1])
    assert cells[k - 1]["cell_type"] == "markdown"
    assert "Colab" in note and "mpiexec" in note and "own machine" in note


def test_every_lesson_has_a_colab_and_a_binder_badge():
    readme = (REPO_ROOT / "lessons" / "README.md").read_text(encoding="utf-8")
    update_links = load_update_links()
    # The table is what the script writes from REPOSITORY_URL (a fork reruns it).
    assert update_links.with_badges(readme, NOTEBOOKS) == readme
    for path in NOTEBOOKS:
        target = f"lessons/{path.name}"
        assert notebook.colab_url(target) in readme and notebook.binder_url(target) in readme
    assert "must" in readme and "REPOSITORY_URL" in readme  # forks are told to change it


def test_the_readme_links_the_lessons_in_colab_and_binder():
    readme = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## The lessons"):]
    section = section[:section.index("\n## ", 1)]
    assert notebook.binder_url() in section
    assert notebook.colab_url("lessons/01_rl_and_the_bellman_equation.ipynb") in section


def test_the_links_are_built_from_the_repository_address(monkeypatch):
    monkeypatch.setattr(notebook, "REPOSITORY_URL", "https://github.com/someone/fork")
    assert notebook.colab_url("lessons/01_x.ipynb") == \
        "https://colab.research.google.com/github/someone/fork/blob/main/lessons/01_x.ipynb"
    assert notebook.binder_url("lessons/01_x.ipynb") == \
        "https://mybinder.org/v2/gh/someone/fork/main?labpath=lessons%2F01_x.ipynb"
    assert "https://github.com/someone/fork" in notebook.install_cell_source()


def test_binder_installs_the_course_with_the_cpu_torch_pin():
    post_build = REPO_ROOT / "binder" / "postBuild"
    assert os.access(post_build, os.X_OK)
    text = post_build.read_text()
    assert "-c constraints.txt" in text and "https://download.pytorch.org/whl/cpu" in text
    assert '-e ".[notebooks,mpi]"' in text
    assert (REPO_ROOT / "constraints.txt").read_text().count("torch==") == 1
    assert (REPO_ROOT / "binder" / "runtime.txt").read_text().startswith("python-3.")
