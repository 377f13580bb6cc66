"""Grading: lesson 10, generalisation (reference: dlo_course.evaluation)."""

import numpy as np
import pytest

from dlo_course.evaluation import EpisodeRecord, summarize, wilson_interval

pytestmark = pytest.mark.notebook("10_generalisation")


@pytest.mark.exercise("table_row", points=2)
def test_table_row(exercise):
    rng = np.random.default_rng(10)
    for n in (1, 7, 1000):
        done = rng.random(n) < 0.8
        final = np.where(done, rng.uniform(0.02, 0.05, n), rng.uniform(0.05, 0.3, n))
        records = [EpisodeRecord(i, 0, bool(d), float(f), 30, 0.2)
                   for i, (d, f) in enumerate(zip(done, final))]
        expected = summarize(records)
        got = exercise(list(done), list(final))
        for key in ("done_percent", "mean_distance", "std_distance", "best_distance"):
            assert key in got, f"missing {key!r}"
            assert float(got[key]) == pytest.approx(getattr(expected, key), rel=1e-9,
                                                    abs=1e-12), key


@pytest.mark.exercise("wilson_interval", points=2)
def test_wilson_interval(exercise):
    for k, n in [(995, 1000), (0, 10), (10, 10), (3, 7), (211, 1000), (1, 1), (500, 1000)]:
        got = tuple(float(x) for x in exercise(k, n))
        assert got == pytest.approx(wilson_interval(k, n), rel=1e-9, abs=1e-12), f"({k}, {n})"
        assert 0.0 <= got[0] <= k / n + 1e-12 and k / n - 1e-12 <= got[1] <= 1.0
    assert tuple(exercise(7, 20, z=2.576)) == pytest.approx(wilson_interval(7, 20, z=2.576))
    for bad in [(1, 0), (-1, 10), (11, 10)]:
        with pytest.raises(ValueError):
            exercise(*bad)
