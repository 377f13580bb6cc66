"""No lesson uses a training lever before a lesson teaches it (issue 30).

A **training lever** is a configuration field that changes what the training algorithm does
(as opposed to its budget, its bookkeeping, or the paper's own hyperparameters, which lessons
1-4 teach): every field of :class:`TrainConfig` and :class:`DDPGConfig` except those in
:data:`NOT_LEVERS`. A test below makes sure every field is classified, so a new field has to
be put on one side or the other.

A code cell of a solution notebook **switches a lever on** when it (detection is deliberately
simple, on the cell's syntax tree):

* names a preset: ``preset("recipe", ...)`` or the two strings ``"--preset", "recipe"`` side
  by side in a list or tuple (a command line). The preset switches on every lever whose value
  differs from ``PRESETS["paper"]``'s (:func:`preset_levers`, computed from
  ``dlo_course.config.PRESETS``);
* passes a lever as a keyword argument (``DDPGConfig(twin_critics=True)``,
  ``preset(..., her_k=4)``, ``dataclasses.replace(config, her_k=4)``) with a value that is not
  a literal equal to the paper's;
* has a command-line flag of a lever in a list or tuple: ``"--her-k", "4"`` (the field's name
  with dashes, followed by its value), ``"--twin-critics"`` (a boolean), ``"--no-..."`` or
  ``"--keep-shape"`` (:data:`FLAG_ALIASES`). A value equal to the paper's is not a use.

A lever is **taught** by a Markdown cell holding ``<!-- teaches: name, name, ... -->`` (field
names) in an earlier lesson, or earlier in the same notebook. Lessons are ordered by their
number.
"""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import pytest

from dlo_course.config import PRESETS, DDPGConfig, TrainConfig, config_fields
from dlo_course.grading import notebooks

NOT_LEVERS = {
    # the task, the budget and the bookkeeping of a run
    "env_id", "env_kwargs", "episodes", "steps_per_episode", "seed", "out_dir",
    "checkpoint_every", "expected_agents", "validation_goals", "validation_steps",
    "torch_threads",
    # the paper's DDPG hyperparameters and sizes (lessons 1-4)
    "actor_lr", "critic_lr", "batch_size", "buffer_size", "gamma", "tau", "hidden_sizes",
    "final_init", "noise_theta", "noise_sigma", "noise_mu",
}
"""Configuration fields that are not training levers."""

FIELDS = {f.name: cls for cls in (TrainConfig, DDPGConfig) for f in config_fields(cls)}
LEVERS = sorted(set(FIELDS) - NOT_LEVERS)
"""The training levers: every other field."""

FLAG_ALIASES = {"--keep-shape": ("reset_between_episodes", False)}
"""Command-line flags that are not ``--field-name`` or ``--no-field-name``."""

TEACHES = re.compile(r"<!--\s*teaches:\s*([^>]*?)\s*-->", re.IGNORECASE)


def paper_value(name: str):
    """The field's value in the ``paper`` preset."""
    paper = PRESETS["paper"]
    return getattr(paper.ddpg if FIELDS[name] is DDPGConfig else paper, name)


def preset_levers(name: str) -> set[str]:
    """The levers preset ``name`` sets to a value other than the paper preset's."""
    config = PRESETS[name]
    return {lever for lever in LEVERS
            if getattr(config.ddpg if FIELDS[lever] is DDPGConfig else config, lever)
            != paper_value(lever)}


def _literal(node: ast.AST):
    try:
        return ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return _literal  # not a literal: a sentinel equal to nothing


def _same_as_paper(name: str, value) -> bool:
    if value is _literal:
        return False
    paper = paper_value(name)
    if isinstance(paper, bool) or isinstance(value, bool):
        return value is paper
    if isinstance(value, str):  # a command-line value
        try:
            return type(paper)(float(value)) == paper if paper is not None else False
        except ValueError:
            return False
    return value == paper


def _flag_lever(flag: str) -> tuple[str, object] | None:
    """(field, value implied or None when a value follows) of a command-line flag."""
    if flag in FLAG_ALIASES:
        return FLAG_ALIASES[flag]
    name = flag[2:].replace("-", "_")
    if name.startswith("no_") and name[3:] in LEVERS and isinstance(paper_value(name[3:]), bool):
        return name[3:], False
    if name in LEVERS:
        return (name, True) if isinstance(paper_value(name), bool) else (name, None)
    return None


def levers_used(source: str) -> set[str]:
    """The levers a code cell switches on (see the module's docstring)."""
    try:
        tree = ast.parse(source)
    except SyntaxError:  # IPython syntax: drop the magics and shell lines
        tree = ast.parse("\n".join(line for line in source.splitlines()
                                   if not line.lstrip().startswith(("%", "!"))))
    used: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            called = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
            if called == "preset" and node.args and isinstance(node.args[0], ast.Constant) \
                    and node.args[0].value in PRESETS:
                used |= preset_levers(node.args[0].value)
            for keyword in node.keywords:
                if keyword.arg in LEVERS and not _same_as_paper(keyword.arg,
                                                                 _literal(keyword.value)):
                    used.add(keyword.arg)
        elif isinstance(node, (ast.List, ast.Tuple)):
            items = [item.value if isinstance(item, ast.Constant) else _literal
                     for item in node.elts]
            for i, item in enumerate(items):
                if not (isinstance(item, str) and item.startswith("--")):
                    continue
                following = items[i + 1] if i + 1 < len(items) else _literal
                if item == "--preset" and following in PRESETS:
                    used |= preset_levers(following)
                    continue
                found = _flag_lever(item)
                if found is None:
                    continue
                name, value = found
                if value is None:
                    value = following
                if not _same_as_paper(name, value):
                    used.add(name)
    return used


def taught_in(source: str) -> set[str]:
    """The levers a Markdown cell's ``teaches:`` markers name."""
    return {name.strip() for marker in TEACHES.findall(source)
            for name in marker.split(",") if name.strip()}


def violations(paths: list[Path]) -> list[str]:
    """"lesson, cell: lever" for every lever used before it is taught, ``paths`` in course
    order."""
    taught: set[str] = set()
    found = []
    for path in paths:
        nb = notebooks.read_notebook(path)
        for index, cell in enumerate(nb["cells"]):
            source = notebooks.cell_source(cell)
            if cell["cell_type"] == "markdown":
                taught |= taught_in(source)
            elif cell["cell_type"] == "code":
                for lever in sorted(levers_used(source) - taught):
                    found.append(f"{path.stem}, cell {index}: {lever} is used before any "
                                 f"lesson teaches it (a `<!-- teaches: {lever} -->` marker)")
    return found


def solution_notebooks() -> list[Path]:
    return sorted(notebooks.SOLUTIONS_DIR.glob(notebooks.NOTEBOOK_GLOB))


def test_every_field_is_classified():
    assert NOT_LEVERS <= set(FIELDS), NOT_LEVERS - set(FIELDS)
    assert {"her_k", "twin_critics", "normalize_obs", "preactivation_l2"} <= set(LEVERS)


def test_the_recipe_switches_on_the_levers_lesson_9_teaches():
    assert preset_levers("paper") == set()
    assert preset_levers("recipe") >= {
        "normalize_obs", "preactivation_l2", "twin_critics", "policy_delay", "target_noise",
        "target_noise_clip", "her_k", "updates_per_step", "reset_between_episodes"}


def test_markers_name_real_levers():
    for path in solution_notebooks():
        for cell in notebooks.read_notebook(path)["cells"]:
            if cell["cell_type"] == "markdown":
                unknown = taught_in(notebooks.cell_source(cell)) - set(LEVERS)
                assert not unknown, f"{path.name}: teaches unknown levers {sorted(unknown)}"


def test_detection():
    assert levers_used('config = preset("recipe", episodes=3)') == preset_levers("recipe")
    assert levers_used('cmd = ["dlo-course", "train", "--preset", "course"]') == \
        preset_levers("course")
    assert levers_used("DDPGConfig(twin_critics=True, target_noise_clip=0.5)") == \
        {"twin_critics"}  # 0.5 is the paper's clip: not a use
    assert levers_used("replace(config, her_k=k)") == {"her_k"}  # not a literal: a use
    assert levers_used('opts = ["--her-k", "4", "--keep-shape", "--validate-every", "0"]') == \
        {"her_k", "reset_between_episodes"}
    assert levers_used('opts = ["--twin-critics", "--no-stop-at-goal", "--batch-size", "4"]') \
        == {"twin_critics"}
    assert levers_used("print(config.her_k, PRESETS['recipe'].ddpg.twin_critics)") == set()
    assert taught_in("text <!-- teaches: her_k, twin_critics -->") == {"her_k", "twin_critics"}


def _synthetic(folder: Path, name: str, cells: list[tuple[str, str]]) -> Path:
    nb = {"cells": [{"cell_type": kind, "metadata": {}, "source": source,
                     **({"outputs": [], "execution_count": None} if kind == "code" else {})}
                    for kind, source in cells],
          "metadata": {}, "nbformat": 4, "nbformat_minor": 5}
    return notebooks.write_notebook(nb, folder / name)


def test_an_untaught_lever_fails(tmp_path):
    early = _synthetic(tmp_path, "01_early.ipynb", [
        ("markdown", "Training with hindsight. <!-- teaches: her_k -->"),
        ("code", "config = TrainConfig(her_k=4)")])
    late = _synthetic(tmp_path, "02_late.ipynb", [
        ("code", 'train(preset("smoke", her_k=2))'),
        ("code", 'run(["--preset", "recipe"])'),
        ("markdown", "<!-- teaches: twin_critics -->"),
        ("code", "DDPGConfig(twin_critics=True)")])
    found = violations([early, late])
    assert found, "a notebook that uses untaught levers must fail"
    joined = "\n".join(found)
    assert "02_late, cell 1: normalize_obs" in joined  # from the recipe preset
    assert "02_late, cell 1: twin_critics" in joined  # used before its marker
    assert "her_k" not in joined  # taught by the earlier lesson
    assert "cell 3" not in joined  # taught just before
    # without the earlier lesson, her_k is untaught too
    assert any("02_late, cell 0: her_k" in v for v in violations([late]))


def test_no_lesson_uses_a_lever_before_it_is_taught():
    found = violations(solution_notebooks())
    assert not found, "\n".join(found)
