"""Grading: lesson 10, generalisation (reference: dlo_course.evaluation)."""

import numpy as np
import pytest

from dlo_course.evaluation import EpisodeRecord, summarize, wilson_interval

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


# ------------------------------------------------------------------ written answers


@pytest.mark.exercise("prediction_verdicts", points=1)
def test_prediction_verdicts(written_answer):
    written_answer.check()
