"""Grading: lesson 13, the capstone on Table I (references: dlo_course.evaluation.wilson_interval,
dlo_course.reproduce.verdict).

``done_interval`` is compared with the library's Wilson interval on done % values as the
reproduction's CSV stores them (rounded to 6 significant digits), ``paper_verdict`` with the
library's verdict on values that sit exactly on the ends of an interval, and
``count_not_worse`` with a count made here from the library's verdicts, on rows where
counting the wrong verdicts gives another number. The written answers (Markdown cells) are
never run: they score for presence and length, and their text goes to the instructor.

The probes below run in the grading sandbox, the checks here.
"""

import pytest

from dlo_course.evaluation import wilson_interval
from dlo_course.reproduce import verdict

pytestmark = pytest.mark.notebook("13_capstone_table_one")

# (done %, episodes) as the CSV writes them: 0 and 100 %, thirds, the paper's 1000 episodes
INTERVAL_CASES = [(40.0, 20), (5.0, 20), (0.0, 20), (100.0, 100), (87.0, 100),
                  (33.3333, 3), (66.6667, 3), (99.5, 1000), (57.0, 100), (100.0, 1), (0.0, 1)]


def library_interval(done_percent, episodes, z=1.959964):
    successes = round(done_percent * episodes / 100)
    return tuple(100 * x for x in wilson_interval(successes, episodes, z=z))


def probe_done_interval(fn, cases):
    return {"intervals": [tuple(float(x) for x in fn(p, n)) for p, n in cases],
            "z": tuple(float(x) for x in fn(35.0, 20, z=2.576))}


@pytest.mark.exercise("done_interval", points=2,
                      reference="dlo_course.evaluation.wilson_interval")
def test_done_interval(student):
    got = student.run(probe_done_interval, INTERVAL_CASES)
    for (p, n), interval in zip(INTERVAL_CASES, got["intervals"], strict=True):
        want = library_interval(p, n)
        assert interval == pytest.approx(want, rel=1e-9, abs=1e-9), (
            f"done {p}% of {n} episodes: {interval}, expected {want} (percent, Wilson, "
            f"successes = round(done % x episodes / 100))")
    assert got["z"] == pytest.approx(library_interval(35.0, 20, z=2.576), rel=1e-9), \
        "the z argument must set the interval's width"


# (paper done %, low, high): on each side, inside, and exactly on both ends
VERDICT_CASES = [(99.5, 21.9, 61.3), (13.9, 0.0, 16.1), (70.0, 79.0, 92.2), (99.1, 96.3, 100.0),
                 (96.3, 96.3, 100.0), (100.0, 96.3, 100.0), (0.0, 0.0, 16.1),
                 (16.1, 0.0, 16.1), (16.2, 0.0, 16.1), (78.9, 79.0, 92.2)]


def probe_paper_verdict(fn, cases):
    return [str(fn(paper, low, high)) for paper, low, high in cases]


@pytest.mark.exercise("paper_verdict", points=1, reference="dlo_course.reproduce.verdict")
def test_paper_verdict(student):
    got = student.run(probe_paper_verdict, VERDICT_CASES)
    for (paper, low, high), mine in zip(VERDICT_CASES, got, strict=True):
        want = verdict({"done_ci_low": low, "done_ci_high": high}, paper)
        assert mine == want, f"paper {paper}%, our interval [{low}, {high}]: {mine!r}, " \
                             f"expected {want!r}"


def count_rows():
    """Table-like rows with 4 verdicts "above", 5 "within" (2 of them on an end of the
    interval) and 6 "below"."""
    rows = []
    for p, n, paper in [(100.0, 100, 90.0), (87.0, 100, 73.4), (40.0, 20, 10.0),
                        (100.0, 1000, 99.0),                                  # above
                        (100.0, 100, 99.5), (81.0, 100, 80.2), (5.0, 20, 21.1),
                        (0.0, 20, 0.0), (100.0, 20, 100.0),                   # within
                        (87.0, 100, 99.8), (57.0, 100, 88.7), (40.0, 20, 99.5),
                        (0.0, 20, 73.4), (10.0, 20, 46.8), (35.0, 20, 99.8)]:  # below
        rows.append({"done_percent": p, "episodes": n, "paper_done_percent": paper})
    return rows


def check_verdicts(rows):
    """The library's verdict of each row, its interval computed from done % and episodes."""
    found = []
    for row in rows:
        low, high = library_interval(row["done_percent"], row["episodes"])
        found.append(verdict({"done_ci_low": low, "done_ci_high": high},
                             row["paper_done_percent"]))
    return found


def probe_count_not_worse(fn, rows):
    everything = fn([dict(row) for row in rows])
    every_other = fn([dict(row) for row in rows[::2]])
    nothing = fn([])
    return [int(everything), int(every_other), int(nothing)]


@pytest.mark.exercise("count_not_worse", points=2,
                      reference=("dlo_course.evaluation.wilson_interval",
                                 "dlo_course.reproduce.verdict"))
def test_count_not_worse(student):
    rows = count_rows()
    found = check_verdicts(rows)
    assert [found.count(v) for v in ("above", "within", "below")] == [4, 5, 6]  # the test's data
    want = [sum(v != "below" for v in check_verdicts(subset)) for subset in (rows, rows[::2])]
    got = student.run(probe_count_not_worse, rows)
    assert got == want + [0], (f"counts {got} for the rows, every other row and no row; "
                               f"expected {want + [0]}: count the verdicts \"above\" and "
                               f"\"within\"")


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_cells", points=1)
def test_prediction_cells(written_answer):
    written_answer.check()


@pytest.mark.exercise("prediction_factor", points=1)
def test_prediction_factor(written_answer):
    written_answer.check()


@pytest.mark.exercise("analysis_comparison", points=2)
def test_analysis_comparison(written_answer):
    written_answer.check()


@pytest.mark.exercise("analysis_next_step", points=1)
def test_analysis_next_step(written_answer):
    written_answer.check()
