"""Grading: lesson 10, generalisation (reference: dlo_course.evaluation; the verdict:
dlo_course.reproduce.done_verdict)."""

import numpy as np
import pytest

from dlo_course.evaluation import EpisodeRecord, summarize, wilson_interval
from dlo_course.reproduce import done_verdict

pytestmark = pytest.mark.notebook("10_generalisation")

KEYS = ("done_percent", "mean_distance", "std_distance", "best_distance")


def table_cases():
    """Fixed sizes (one episode, a few, Table I's 1000), then a fresh random size."""
    rng = np.random.default_rng()  # fresh episodes at every grading
    for n in (1, 7, 1000, int(rng.integers(2, 300))):
        done = rng.random(n) < 0.8
        final = np.where(done, rng.uniform(0.02, 0.05, n), rng.uniform(0.05, 0.3, n))
        yield [bool(d) for d in done], [float(f) for f in final]


def probe_table_row(fn, cases):
    out = []
    for done, final in cases:
        row = fn(list(done), list(final))
        out.append({key: float(row[key]) for key in KEYS if key in row})
    return out


@pytest.mark.exercise("table_row", points=2, reference="dlo_course.evaluation.summarize")
def test_table_row(student):
    cases = list(table_cases())
    got = student.run(probe_table_row, cases)
    for row, (done, final) in zip(got, cases, strict=True):
        expected = summarize([EpisodeRecord(i, 0, d, f, 30, 0.2)
                              for i, (d, f) in enumerate(zip(done, final))])
        for key in KEYS:
            assert key in row, f"missing {key!r}"
            assert row[key] == pytest.approx(getattr(expected, key), rel=1e-9, abs=1e-12), key


WILSON_CASES = [(995, 1000), (0, 10), (10, 10), (3, 7), (211, 1000), (1, 1), (500, 1000)]
WILSON_BAD = [(1, 0), (-1, 10), (11, 10)]


def wilson_cases():
    """The fixed edges (0%, 100%, one trial), then fresh random counts."""
    rng = np.random.default_rng()  # fresh counts at every grading
    drawn = []
    for _ in range(20):
        n = int(rng.integers(1, 2000))
        drawn.append((int(rng.integers(0, n + 1)), n))
    return WILSON_CASES + drawn


def probe_wilson_interval(fn, cases):
    raised = []
    for bad in WILSON_BAD:
        try:
            fn(*bad)
            raised.append(None)
        except Exception as err:  # noqa: BLE001
            raised.append(type(err).__name__)
    return {"intervals": [tuple(float(x) for x in fn(k, n)) for k, n in cases],
            "z": tuple(float(x) for x in fn(7, 20, z=2.576)), "raised": raised}


@pytest.mark.exercise("wilson_interval", points=2,
                      reference="dlo_course.evaluation.wilson_interval")
def test_wilson_interval(student):
    cases = wilson_cases()
    got = student.run(probe_wilson_interval, cases)
    for (k, n), interval in zip(cases, got["intervals"], strict=True):
        assert interval == pytest.approx(wilson_interval(k, n), rel=1e-9, abs=1e-12), f"({k}, {n})"
        assert 0.0 <= interval[0] <= k / n + 1e-12 and k / n - 1e-12 <= interval[1] <= 1.0
    assert got["z"] == pytest.approx(wilson_interval(7, 20, z=2.576))
    for bad, raised in zip(WILSON_BAD, got["raised"], strict=True):
        assert raised == "ValueError", f"wilson_interval{bad} must raise ValueError ({raised})"


# (successes, episodes, paper's done %): 4 verdicts "above", 5 "within" (2 of them on an end of
# the interval: 0 of 20 against 0%, 20 of 20 against 100%) and 6 "below"; naming the verdicts
# from the paper's side, leaving the ends out of the interval or comparing percent with
# fractions each changes some of them.
VERDICT_CASES = [(100, 100, 90.0), (87, 100, 73.4), (8, 20, 10.0), (1000, 1000, 99.0),
                 (100, 100, 99.5), (81, 100, 80.2), (1, 20, 21.1), (0, 20, 0.0),
                 (20, 20, 100.0), (87, 100, 99.8), (57, 100, 88.7), (8, 20, 99.5),
                 (0, 20, 73.4), (2, 20, 46.8), (7, 20, 99.8)]


def verdict_cases():
    """The fixed cases, then fresh ones. (No fresh paper value sits on an end of the interval:
    a correct Wilson interval computed in another order may differ there in the last bit.)"""
    rng = np.random.default_rng()  # fresh cases at every grading
    drawn = []
    for _ in range(30):
        n = int(rng.integers(1, 1500))
        drawn.append((int(rng.integers(0, n + 1)), n, float(rng.uniform(0, 100))))
    return VERDICT_CASES + drawn


def probe_table_verdict(fn, cases):
    return [str(fn(k, n, paper)) for k, n, paper in cases]


@pytest.mark.exercise("table_verdict", points=2, reference="dlo_course.reproduce.done_verdict")
def test_table_verdict(student):
    fixed = [done_verdict(*case) for case in VERDICT_CASES]
    assert [fixed.count(v) for v in ("above", "within", "below")] == [4, 5, 6]  # the test's data
    cases = verdict_cases()
    got = student.run(probe_table_verdict, cases)
    for case, value in zip(cases, got, strict=True):
        assert value == done_verdict(*case), (
            f"table_verdict{case} = {value!r}, expected {done_verdict(*case)!r}: \"above\" when "
            f"the paper's done % is below our interval (in percent, its ends included)")


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_verdicts", points=1)
def test_prediction_verdicts(written_answer):
    written_answer.check()
