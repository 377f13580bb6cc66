"""Lesson 05's sub-step bracket (issue 51): the protocol's runs, the bound between them, the
table the lesson reads, and the committed bracket that the lesson's text quotes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from dlo_course import simulation
from dlo_course.notebook import markdown_tables
from dlo_course.simulation import (BROKEN_STRETCH, StabilityRun, bracket_bound, bracket_table,
                                   stability_run)

REPO = Path(__file__).resolve().parent.parent
BRACKET = REPO / "benchmarks" / "results" / "substep_bracket.md"
LESSON = REPO / "solutions" / "05_soft_bodies_in_pybullet.ipynb"


def made_up(sub_steps, stretch, blew_up_at=None, actions=4) -> StabilityRun:
    stretch = np.asarray(stretch, dtype=float)
    return StabilityRun(sub_steps=sub_steps, time_step=0.003, physics_per_action=0.003,
                        actions=actions, spread=np.full(len(stretch), 1.6), stretch=stretch,
                        blew_up_at=blew_up_at, seconds=1.0)


def test_a_rod_breaks_at_the_first_stretched_edge_or_at_its_blow_up():
    held = made_up(20, [1.0, 1.02, 1.01, 1.0])
    assert held.stable and held.broke_at is None and held.sub_step == pytest.approx(0.00015)
    torn = made_up(2, [1.0, 1.5, BROKEN_STRETCH + 1, 40.0], blew_up_at=None)
    assert not torn.stable and torn.broke_at == 3 and torn.physics_time(3) == pytest.approx(0.009)
    flown = made_up(1, [1.0, 1.1], blew_up_at=3)  # blew up before any edge was torn
    assert flown.broke_at == 3 and not flown.stable
    assert "in one piece" in held.summary() and "broke after 9 ms" in torn.summary()
    assert "blew up after 9 ms" in flown.summary() and " 1 sub-step of 3 ms" in flown.summary()


def test_the_bound_lies_between_the_largest_that_held_and_the_smallest_that_broke():
    runs = [made_up(20, [1.0]), made_up(4, [1.2]), made_up(3, [5.0]), made_up(1, [9.0])]
    held, broke = bracket_bound(runs)
    assert (held.sub_steps, broke.sub_steps) == (4, 3)
    assert bracket_bound(runs[:2]) == (runs[1], None)
    assert bracket_bound(runs[2:]) == (None, runs[2])


def test_the_table_has_the_columns_the_lesson_reads(tmp_path):
    runs = [made_up(20, [1.0, 1.02]), made_up(2, [1.0, 4.0], blew_up_at=3)]
    for run in runs:
        run.nodes = np.zeros((len(run.stretch), 200, 3))
    runs[0].nodes[1, 5] = 0.003
    path = tmp_path / "t.md"
    path.write_text(bracket_table(runs, runs[0]) + "\n")
    rows = markdown_tables(path)[0]
    assert [r["sub-step (ms)"] for r in rows] == ["0.15", "1.5"]
    assert rows[0]["outcome"].startswith("in one piece") and rows[1]["outcome"] == "blew up"
    assert rows[1]["broke after (ms)"] == "6" and rows[1]["blew up after (ms)"] == "9"
    assert rows[0]["largest node gap to 20 sub-steps (mm)"] == "0" and rows[0]["wall time (s)"]


@pytest.mark.slow
def test_the_protocol_holds_at_the_authors_sub_step_and_breaks_at_one_per_action():
    held = stability_run(20, actions=4, keep_nodes=True)
    assert held.stable and held.nodes.shape == (4, 200, 3) and held.stretch.max() < 1.1
    assert held.gap_to(held) == 0.0
    broke = stability_run(1, actions=6)  # the committed bracket: broke after 12 ms
    assert broke.broke_at is not None and broke.broke_at <= 6
    assert simulation.SimParams().sub_steps == simulation.BRACKET_SUB_STEPS[0]
    assert simulation.BRACKET_SUB_STEPS[-1] == 1


def bracket_passes():
    return markdown_tables(BRACKET)


def lesson_markdown() -> str:
    cells = json.loads(LESSON.read_text(encoding="utf-8"))["cells"]
    return " ".join(" ".join("".join(c["source"]).split()) for c in cells
                    if c["cell_type"] == "markdown")


def row(rows, sub_step_ms):
    return next(r for r in rows if r["sub-step (ms)"] == sub_step_ms)


def test_the_committed_bracket_runs_from_the_authors_sub_step_to_one_per_action():
    text = BRACKET.read_text(encoding="utf-8")
    assert "`python -m dlo_course.simulation --out benchmarks/results/substep_bracket.md`" in text
    passes = bracket_passes()
    assert len(passes) == 3
    for rows in passes:
        assert [int(r["sub-steps per action"]) for r in rows] == list(simulation.BRACKET_SUB_STEPS)
    assert "node positions identical to the first pass: yes" in text


def test_lesson_05_quotes_the_committed_bracket():
    """The numbers lesson 05's text states of the bracket are the committed file's (the cell
    beside the text prints them from it)."""
    gentle, again, hard = bracket_passes()
    md = lesson_markdown()
    text = BRACKET.read_text(encoding="utf-8")
    # the bound: held up to 0.75 ms, broke from 1 ms; a full-speed push: 0.6 ms held, 0.75 broke
    assert "in one piece up to 0.75 ms (4 sub-steps per action); broke from 1 ms" in text
    assert "in one piece up to 0.6 ms (5 sub-steps per action); broke from 0.75 ms" in text
    assert "up to 0.75 ms (4 per action" in md and "broke from 1 ms (3 per action, after 27 ms)" in md
    assert "0.6 ms held, 0.75 ms broke after 93 ms" in md
    assert row(hard, "0.75")["broke after (ms)"] == "93"
    assert "in one piece over 1000 actions" in text and "over 1000, 3 s of physics" in md
    # the break times, in order, and the blow-up times of both passes
    breaks = {s: row(gentle, s)["broke after (ms)"] for s in ("3", "1.5", "1")}
    assert breaks == {"3": "12", "1.5": "18", "1": "27"}
    assert breaks == {s: row(again, s)["broke after (ms)"] for s in breaks}
    assert "3 ms after 12 ms, 1.5 ms after 18 ms, 1 ms after 27 ms" in md
    blown = [(row(p, "1")["blew up after (ms)"], row(p, "3")["blew up after (ms)"])
             for p in (gentle, again)]
    assert blown == [("51", "162"), ("63", "111")]
    assert row(gentle, "1.5")["blew up after (ms)"] == "27"
    assert "took 162 ms to trip the test, against 27 ms at 1.5 ms" in md
    assert "(1 ms: 51, then 63 ms; 3 ms: 162, then 111 ms)" in md


def test_lesson_05_no_longer_calls_the_estimate_the_limit():
    md = lesson_markdown()
    assert "right at the authors' sub-step" not in md
    assert not re.search(r"~\s*0\.15 ms", md)
    assert "unstable runs are the fast ones" not in md
