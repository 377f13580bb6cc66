"""The per-episode evaluations of the shipped agents (benchmarks/results/shipped/), which lesson
10 reads as "the shipped agents against the paper", are of today's agents, and are the episodes
of Table I's small-database cells with reinitialisation in docs/reproduction/.

Lesson 10 once read the evaluations of agents replaced two issues earlier, under the heading of
the shipped ones: the digest check fails as soon as an agent is reshipped without them.
"""

import csv
import json

import pytest

from dlo_course.evaluation import EpisodeRecord, summarize
from dlo_course.paths import AGENTS_DIR, REPO_ROOT
from dlo_course.reproduce import actor_digest

SHIPPED = REPO_ROOT / "benchmarks" / "results" / "shipped"
TABLE = REPO_ROOT / "docs" / "reproduction" / "table1.csv"


@pytest.mark.parametrize("nodes", (2, 4, 6))
def test_each_shipped_agent_has_its_episodes_and_they_are_table_ones(nodes):
    readme = (SHIPPED / "README.md").read_text()
    assert actor_digest(AGENTS_DIR / f"nodes{nodes}") in readme, (
        f"benchmarks/results/shipped/ is not of today's nodes{nodes}: remake it with the "
        f"command of its README")
    entries = json.loads((SHIPPED / f"nodes{nodes}_small_test_reinit.json").read_text())
    with open(TABLE, newline="") as f:
        table = {float(r["threshold"]): r for r in csv.DictReader(f)
                 if (r["reinit"], int(r["nodes"]), r["database"]) == ("with", nodes, "small")}
    assert sorted(e["threshold"] for e in entries) == sorted(table)
    for entry in entries:
        # summarised from the episodes themselves, not read from the file's own summary
        summary = summarize([EpisodeRecord(**e) for e in entry["episodes"]])
        row = table[entry["threshold"]]
        assert summary.episodes == int(row["episodes"]) == 100
        # a deterministic simulation, the same goals and seed: Table I's very episodes
        assert summary.done_percent == pytest.approx(float(row["done_percent"]))
        assert summary.mean_distance == pytest.approx(float(row["mean_distance"]), rel=1e-5)
