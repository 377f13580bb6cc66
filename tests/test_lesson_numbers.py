"""Every measured number a lesson's markdown states is printed by a cell, or says where it came from.

A number passes when either

- a code cell of the same notebook reads a committed results file (its path appears in the
  cell's source) and that file contains the number's evidence string, so the cell prints it; or
- the markdown cell that states it also says "measured offline with `<command>`".

``NUMBERS`` lists the ones the course checked by hand (project issue 30); the generic test flags
any other percentage or "± number" in the markdown of the lessons that quote measurements.
"""

import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SOLUTIONS = REPO / "solutions"
OFFLINE = "measured offline with `"

# (notebook stem, number as written in the markdown, results file a cell reads or None,
#  the string that file holds for it)
NUMBERS = [
    ("04_ddpg", "−112.0 ± 66.1", "benchmarks/results/ddpg_pendulum.txt", "-112.0 +- 66.1"),
    ("07_deformation_databases", "97%", None, None),
    ("07_deformation_databases", "67.5%", None, None),
    ("12_hindsight_relabelling", "62%", "benchmarks/results/ablation/README.md", "| 62 (52-71)"),
    ("12_hindsight_relabelling", "95%", "benchmarks/results/ablation/README.md", "| 95 (89-98)"),
    ("12_hindsight_relabelling", "27%", "benchmarks/results/ablation/README.md", "| 27 (19-36)"),
    ("12_hindsight_relabelling", "78%", "benchmarks/results/ablation/README.md", "| 78 (69-85)"),
    ("15_why_ddpg_stalls", "−120 and −115", None, None),
    ("15_why_ddpg_stalls", "42%", None, None),
    ("15_why_ddpg_stalls", "about 17", None, None),
    ("15_why_ddpg_stalls", "correlation of 0.51", "benchmarks/results/dlo_nodes4_2ranks.md",
     "0.51"),
    ("15_why_ddpg_stalls", "−48.4", "benchmarks/results/dlo_nodes4_2ranks.md", "48.4"),
    ("15_why_ddpg_stalls", "−38.9", "benchmarks/results/dlo_nodes4_2ranks.md", "38.9"),
    ("15_why_ddpg_stalls", "18 900", "benchmarks/results/dlo_nodes4_2ranks.md", "18 900"),
    ("15_why_ddpg_stalls", "+0.77", "benchmarks/results/dlo_nodes4_2ranks.md", "0.77"),
    ("15_why_ddpg_stalls", "24 m/s", "benchmarks/results/dlo_nodes4_2ranks.md", "24 m/s"),
    ("15_why_ddpg_stalls", "0.57 m", "benchmarks/results/dlo_nodes4_2ranks.md", "0.57"),
    ("15_why_ddpg_stalls", "0–16%", "benchmarks/results/dlo_nodes4_2ranks.md", "0-16"),
    ("15_why_ddpg_stalls", "91%", "benchmarks/results/ablation/README.md", "| 91 (84-95)"),
    ("15_why_ddpg_stalls", "62%", "benchmarks/results/ablation/README.md", "| 62 (52-71)"),
]

# Numbers of the checked lessons that are not measurements: derived in the text or by a cell
# of the lesson itself (tanh gradients, budgets), or bounds. (notebook, number as written)
DERIVED = {
    ("15_why_ddpg_stalls", "6%"),     # 37 800 / 604 800 transitions, both stated beside it
    ("15_why_ddpg_stalls", "2%"),     # 1 - tanh(u)^2 at |tanh(u)| = 0.99, the plotted curve
    ("15_why_ddpg_stalls", "0.02%"),  # 1 - tanh(5)^2
    ("15_why_ddpg_stalls", "1%"),     # 1 - tanh(3)^2
    ("15_why_ddpg_stalls", "95%"),    # a 95% confidence interval, and the ablation's 95 (above)
    ("14_classical_shape_servoing", "95%"),  # the confidence level of the table's intervals
}

CHECKED = ("04_ddpg", "05_soft_bodies_in_pybullet", "07_deformation_databases",
           "12_hindsight_relabelling", "14_classical_shape_servoing", "15_why_ddpg_stalls",
           "16_robustness")

# Settings a lesson's markdown states and one of its code cells prints from the library:
# (notebook, number as written, what the printing cell names, the library's value in the unit
#  written, the value written). The test fails when the library's default moves.
LIBRARY_SETTINGS = [
    ("14_classical_shape_servoing", "3 ms of physics", "physics.physics_time_per_action",
     lambda: 1000 * _sim().SimParams().physics_time_per_action, 3),
    ("14_classical_shape_servoing", "0.06 s per action", "time_mode='paper'",
     lambda: _sim().SimParams(time_mode="paper").physics_time_per_action, 0.06),
    ("14_classical_shape_servoing", "1.55 m", "physics.length", lambda: _sim().SimParams().length,
     1.55),
    ("14_classical_shape_servoing", "at most 1 cm per action", '"max_move"',
     lambda: 100 * _servo().JacobianController(n_nodes=4).max_move, 1),
    ("14_classical_shape_servoing", "Broyden gain of 0.3", '"broyden_gain"',
     lambda: _servo().JacobianController(n_nodes=4).broyden_gain, 0.3),
    ("14_classical_shape_servoing", "6 cm per action", "controller.metres_per_action",
     lambda: 100 * _servo().JacobianController(n_nodes=4).metres_per_action, 6),
    ("16_robustness", "2.5 MPa", "base.youngs_modulus / 1e6",
     lambda: _sim().SimParams().youngs_modulus / 1e6, 2.5),
    ("16_robustness", "$\\nu$ = 0.3", "base.poisson_ratio",
     lambda: _sim().SimParams().poisson_ratio, 0.3),
    ("16_robustness", "0.2 kg", "base.mass", lambda: _sim().SimParams().mass, 0.2),
    ("16_robustness", "3 ms of physics", "base.physics_time_per_action",
     lambda: 1000 * _sim().SimParams().physics_time_per_action, 3),
]


def _sim():
    from dlo_course import simulation

    return simulation


def _servo():
    from dlo_course import jacobian

    return jacobian

PERCENT = re.compile(r"(?<![\w.])\d+(?:\.\d+)?%")
PLUS_MINUS = re.compile(r"[−-]?\d+(?:\.\d+)?\s*(?:±|\\pm)\s*\d+(?:\.\d+)?")


def cells(stem):
    nb = json.loads((SOLUTIONS / f"{stem}.ipynb").read_text(encoding="utf-8"))
    return [(c["cell_type"], "".join(c["source"])) for c in nb["cells"]]


def markdown_with(stem, number):
    return [text for kind, text in cells(stem) if kind == "markdown" and number in text]


def read_by_a_cell(stem, results_file):
    return any(kind == "code" and results_file.split("/", 2)[-1] in text
               for kind, text in cells(stem))


@pytest.mark.parametrize("stem, number, results_file, evidence", NUMBERS,
                         ids=[f"{n[0][:2]}:{n[1]}" for n in NUMBERS])
def test_each_listed_number_is_printed_or_marked_offline(stem, number, results_file, evidence):
    texts = markdown_with(stem, number)
    assert texts, f"{stem}: {number!r} is no longer in the markdown (update NUMBERS)"
    for text in texts:
        if OFFLINE in text:
            continue
        assert results_file, f"{stem}: {number!r} needs a cell or '{OFFLINE}...'"
        assert read_by_a_cell(stem, results_file), f"{stem}: no code cell reads {results_file}"
        assert evidence in (REPO / results_file).read_text(encoding="utf-8"), \
            f"{results_file} does not hold {evidence!r} ({stem}: {number!r})"


@pytest.mark.parametrize("stem, number, printed_as, library, written", LIBRARY_SETTINGS,
                         ids=[f"{s[0][:2]}:{s[1]}" for s in LIBRARY_SETTINGS])
def test_each_listed_setting_is_printed_and_is_the_library_s(stem, number, printed_as, library,
                                                            written):
    assert any(" ".join(number.split()) in " ".join(text.split())
               for kind, text in cells(stem) if kind == "markdown"), \
        f"{stem}: {number!r} is no longer in the markdown (update LIBRARY_SETTINGS)"
    assert any(kind == "code" and printed_as in text for kind, text in cells(stem)), \
        f"{stem}: no code cell prints {printed_as} ({number!r})"
    assert library() == pytest.approx(written), \
        f"{stem} says {number!r}, but the library's value is now {library()}"


def test_listed_results_files_exist():
    for stem, number, results_file, _ in NUMBERS:
        if results_file:
            assert (REPO / results_file).is_file(), results_file


def unaccounted_numbers(stem, listed, derived, found_in) -> list[str]:
    """The numbers ``found_in(text)`` finds in ``stem``'s markdown cells that are neither in
    ``listed`` (printed by a cell), nor ``(stem, number)`` in ``derived``, nor in a cell that
    says where it was measured offline."""
    unaccounted = []
    for kind, text in cells(stem):
        if kind != "markdown" or OFFLINE in text:
            continue
        for match in found_in(text):
            if (stem, match) in derived or any(match in number or number in match
                                               for number in listed):
                continue
            unaccounted.append(match)
    return unaccounted


@pytest.mark.parametrize("stem", CHECKED)
def test_measured_numbers_in_markdown_are_accounted_for(stem):
    """Percentages and "x ± y" in the markdown: each listed, derived, or in a cell that says
    where it was measured offline."""
    listed = {number for s, number, _, _ in NUMBERS if s == stem}
    unaccounted = unaccounted_numbers(
        stem, listed, DERIVED, lambda text: [*PERCENT.findall(text), *PLUS_MINUS.findall(text)])
    assert not unaccounted, (f"{stem}: numbers in markdown that no cell prints and no "
                             f"'{OFFLINE}...' covers: {unaccounted}")


def test_the_generic_check_catches_an_unmarked_number(tmp_path):
    text = "The run reached 73% of its goals, a return of −80 ± 12."
    assert PERCENT.findall(text) == ["73%"]
    assert PLUS_MINUS.findall(text) == ["−80 ± 12"]


# ------------------------------------------------------------------ lesson 09 (issue 38)

LESSON_09 = "09_training_ddpg_on_the_dlo"

# Numbers lesson 09's markdown once stated with no cell or committed file behind them: one
# run of section 7 on one machine (its time, episode times and rewards) and that run's
# evaluation, read from the git-ignored reports/ folder. A cell prints them for the
# student's own run; written in the markdown they are caught here.
UNBACKED_09 = ["27 minutes", "1 639 s", "1639 s", "18 to 54 s", "30 s in the median",
               "median 30 s", "-14.6", "-5.3", "100% (95% interval 91-100)", "91-100",
               "91–100", "55% (40-69)", "40-69", "about 6 s per goal"]

# Its percentages that are not measurements: (notebook, number as written)
DERIVED |= {
    (LESSON_09, "6%"),   # 2 x 63 x 300 = 37 800 of the paper's 604 800 transitions
    (LESSON_09, "1%"),   # 2 x 50 x 60 = 6 000 of 604 800, stated beside it
    (LESSON_09, "95%"),  # the confidence level of the intervals
}


def markdown_of(stem):
    return "\n".join(" ".join(text.split()) for kind, text in cells(stem) if kind == "markdown")


@pytest.mark.parametrize("number", UNBACKED_09)
def test_lesson_09_writes_no_number_of_a_run_it_does_not_print(number):
    assert " ".join(number.split()) not in markdown_of(LESSON_09), \
        f"{LESSON_09}: {number!r} is a measurement of one run: print it from a cell"


def test_lesson_09_measured_numbers_in_markdown_are_accounted_for():
    test_measured_numbers_in_markdown_are_accounted_for(LESSON_09)


def test_lesson_09_teaches_the_interval_before_the_first_one_it_shows():
    """The first cell that shows done % intervals (the recipe README's tables) comes after a
    markdown cell that says what a Wilson interval is."""
    kinds = cells(LESSON_09)
    shows = next(i for i, (kind, text) in enumerate(kinds)
                 if kind == "code" and "recipe" in text and "README.md" in text)
    taught = [i for i, (kind, text) in enumerate(kinds)
              if kind == "markdown" and "Wilson" in text and "interval" in text]
    assert taught and taught[0] < shows


def test_lesson_09_shows_the_recipe_readme_with_its_captions_not_bare_tables():
    """Ten bare tables, older agents among them, once stood in the cell: it shows the
    README's first section (the shipped agents, captions included) instead."""
    source = next(text for kind, text in cells(LESSON_09)
                  if kind == "code" and "recipe" in text and "README.md" in text)
    assert "markdown_tables" not in source and '"\\n## "' in source


def test_lesson_09_no_longer_calls_a_few_points_noise():
    """Lesson 11 measures about 20 points between seeds of one configuration."""
    assert "a few points is noise" not in markdown_of(LESSON_09)


# ------------------------------------------------------------------ lessons 10 to 13 (issue 38)
# Their markdown states no measured duration: how long a run took ("about an hour", "151
# minutes") is printed by a cell from a committed file (a record.json, reproduction_time.txt)
# or measured by the cell itself, since retraining the agents changes it. Their percentages
# are the paper's (a cell reads data/paper/table1.csv), confidence levels, or listed here;
# Table I's measured numbers are never written in the markdown (they change with the agents).

LESSONS_10_13 = ("10_generalisation", "11_reproducibility", "12_hindsight_relabelling",
                 "13_capstone_table_one")

NUMBERS_10_13 = [
    ("10_generalisation", "99.5%", "data/paper/table1.csv", ",99.5,"),
    ("10_generalisation", "99.8%", "data/paper/table1.csv", ",99.8,"),
]

# (notebook, number as written): not measurements
DERIVED_10_13 = {
    ("10_generalisation", "99%"),   # "with 99% done": an example of the argument
    ("10_generalisation", "0%"),    # the Wilson interval behaves well near 0% and 100%
    ("10_generalisation", "100%"),
    ("11_reproducibility", "5%"),   # a significance level
    ("13_capstone_table_one", "100%"),  # "near 100%", "nearly every episode"
}

# "95%" as the level of an interval is no measurement; any other 95% is ("at least 95% of the
# goals", lesson 10 before issue 38).
CONFIDENCE_LEVEL = re.compile(r"\b95%(?=\s+(?:\*\*)?(?:confidence|t-intervals?|intervals?|wilson|"
                              r"t-bands?|bands?|ci)\b)", re.IGNORECASE)

# A stated duration of a run: "about an hour", "about eight minutes", "151 min", "1.5 h".
DURATION = re.compile(
    r"(?:\babout\s+(?:an?|one|two|three|four|five|six|seven|eight|nine|ten|twenty|thirty|forty"
    r"|fifty|sixty|ninety|\d+(?:[.,]\d+)?)|(?<![\w.])\d+(?:[.,]\d+)?)\s+"
    r"(?:hours?|h|minutes?|mins?|days?)\b", re.IGNORECASE)


@pytest.mark.parametrize("stem, number, results_file, evidence", NUMBERS_10_13,
                         ids=[f"{n[0][:2]}:{n[1]}" for n in NUMBERS_10_13])
def test_lessons_10_to_13_listed_numbers_are_printed(stem, number, results_file, evidence):
    test_each_listed_number_is_printed_or_marked_offline(stem, number, results_file, evidence)


@pytest.mark.parametrize("stem", LESSONS_10_13)
def test_lessons_10_to_13_state_no_unbacked_number(stem):
    """Durations, percentages and "x ± y" in the markdown of lessons 10-13: each listed,
    derived, or in a cell that says where it was measured offline."""
    listed = {number for s, number, _, _ in [*NUMBERS, *NUMBERS_10_13] if s == stem}

    def found_in(text):
        found = DURATION.findall(text)
        if stem not in CHECKED:  # CHECKED lessons' percentages have their own test above
            text = CONFIDENCE_LEVEL.sub("", text)
            found += [*PERCENT.findall(text), *PLUS_MINUS.findall(text)]
        return found

    unaccounted = unaccounted_numbers(stem, listed, DERIVED_10_13, found_in)
    assert not unaccounted, (f"{stem}: numbers in markdown that no cell prints and no "
                             f"'{OFFLINE}...' covers: {unaccounted}")


@pytest.mark.parametrize("text", [
    "about eight minutes in all with the full budget",  # lesson 11 before issue 38
    "about an hour each on 2 cores",                     # lessons 11, 12 and 13
    "It takes about an hour on two cores",
    "the recipe README says 151 minutes",
    "about 90 min on 2 ranks", "1.5 h of wall time",
])
def test_the_duration_check_catches_a_stated_duration(text):
    assert DURATION.findall(text)


@pytest.mark.parametrize("text", ["0.06 s of physics per action", "3 ms of physics",
                                  "a 30-action test episode", "63 episodes of 300 steps"])
def test_the_duration_check_leaves_settings_alone(text):
    assert not DURATION.findall(text)
