"""The result numbers of README.md and docs/design.md are the committed files' numbers.

Every generated block (``<!-- name:begin -->`` ... ``<!-- name:end -->``) must be exactly what
:mod:`dlo_course.docs_numbers` renders from the committed report, the paper's table, the
shipped agents' records and the benchmark results. After a retraining or a new report,
``python -m dlo_course.docs_numbers`` rewrites them.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from dlo_course import docs_numbers
from dlo_course.docs_numbers import BLOCKS, DOCS, REPO_ROOT, blocks_in, render

README_BLOCKS = {"table1", "agents", "course-size"}
LESSONS_BLOCKS = {"exercises", "course-size"}
DESIGN_BLOCKS = {"ablation", "seeds", "database", "fidelity", "tip-reads", "before-after", "scenes",
                 "speed",
                 "reproduction-time"}


def _text(name: str) -> str:
    return (REPO_ROOT / name).read_text()


@pytest.mark.parametrize("name", DOCS)
def test_blocks_match_the_committed_files(name):
    text = _text(name)
    blocks = blocks_in(text)
    assert set(blocks) <= set(BLOCKS), f"{name}: unknown blocks {set(blocks) - set(BLOCKS)}"
    for block, content in blocks.items():
        assert content == BLOCKS[block](REPO_ROOT), (
            f"{name}: the {block!r} block differs from the committed files; run "
            f"`python -m dlo_course.docs_numbers`")
    assert render(text) == text


def test_each_block_has_its_place():
    assert set(blocks_in(_text("README.md"))) == README_BLOCKS
    assert set(blocks_in(_text("docs/design.md"))) == DESIGN_BLOCKS
    assert set(blocks_in(_text("lessons/README.md"))) == LESSONS_BLOCKS
    assert "<!-- main-job-time -->" in _text("README.md")


def test_table_one_appears_once_in_the_readme():
    readme = _text("README.md")
    assert readme.count("<!-- table1:begin -->") == 1
    # no Table I number outside the generated block: the paper's 4-node small-test 99.8 %
    outside = readme.replace(blocks_in(readme)["table1"], "")
    assert "99.8" not in outside and "88.7" not in outside


def _copy_sources(tmp_path: Path) -> Path:
    for rel in ["docs/reproduction", "data/paper", "benchmarks/results", "README.md",
                "docs/design.md", "lessons/README.md", "solutions", "data/databases/small.npz",
                "data/databases/large.npz"]:
        src, dst = REPO_ROOT / rel, tmp_path / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns("runs", "*.png"))
        else:
            shutil.copy(src, dst)
    for d in (REPO_ROOT / "data/checkpoints").glob("nodes*"):
        (tmp_path / "data/checkpoints" / d.name).mkdir(parents=True)
        for f in ("record.json", "config.json"):
            shutil.copy(d / f, tmp_path / "data/checkpoints" / d.name / f)
    return tmp_path


@pytest.mark.parametrize("table, blocks", [
    ("docs/reproduction/table1.csv", ["README.md: table1"]),
    # the old-scene agents in the new scene: design.md's before/now table
    ("docs/reproduction/before_issue36/table1.csv", ["docs/design.md: scenes"]),
])
def test_a_changed_number_is_caught(tmp_path, table, blocks):
    root = _copy_sources(tmp_path)
    path = root / table
    rows = list(csv.DictReader(path.open()))
    rows[0]["done_percent"] = "42"
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    assert sorted(docs_numbers.stale_blocks(root)) == blocks


def test_a_changed_shipped_actor_is_caught(tmp_path):
    root = _copy_sources(tmp_path)
    path = root / "data/checkpoints/nodes4/record.json"
    record = json.loads(path.read_text())
    record["selected"]["episode"] -= 20  # another validated actor of the same run
    path.write_text(json.dumps(record))
    assert docs_numbers.stale_blocks(root) == ["README.md: agents"]


def test_the_seeds_line_follows_the_seeds_table(tmp_path):
    root = _copy_sources(tmp_path)
    path = root / "benchmarks/results/seeds/table1_seeds.csv"
    before = docs_numbers.table1_markdown(root)
    assert "training seeds of each shipped configuration" in before
    rows = list(csv.DictReader(path.open()))
    row = next(r for r in rows if r["verdict"] == "within")
    row["verdict"] = "below"  # one more cell below the paper
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    after = docs_numbers.table1_markdown(root)
    counted = [line for line in after.splitlines() if "training seeds" in line][0]
    below = sum(r["verdict"] == "below" for r in rows)
    assert f"in {len(rows) - below} of {len(rows)} settings" in counted
    assert f"{row['nodes']} nodes, {row['database']} box, {row['reinit']} reinitialisation" \
        in counted
    assert docs_numbers.stale_blocks(root) == ["README.md: table1"]


def test_a_changed_exercise_is_caught(tmp_path):
    # An exercise worth one point more in a solution: the lessons' table and both totals move.
    root = _copy_sources(tmp_path)
    path = root / "solutions/02_experience_replay.ipynb"
    nb = json.loads(path.read_text())
    cell = next(c for c in nb["cells"] if (c["metadata"].get("dlo_course") or {}).get("exercise"))
    cell["metadata"]["dlo_course"]["points"] += 1
    path.write_text(json.dumps(nb))
    assert sorted(docs_numbers.stale_blocks(root)) == [
        "README.md: course-size", "lessons/README.md: course-size", "lessons/README.md: exercises"]


def test_the_paper_numbers_must_agree(tmp_path):
    root = _copy_sources(tmp_path)
    path = root / "data/paper/table1.csv"
    path.write_text(path.read_text().replace("99.8", "99.7"))
    with pytest.raises(ValueError, match="paper done %"):
        docs_numbers.table1_markdown(root)


def test_default_train_threshold_is_the_tasks():
    from dlo_course.task import TRAIN_THRESHOLD

    assert docs_numbers.DEFAULT_TRAIN_THRESHOLD == TRAIN_THRESHOLD


def test_the_module_map_names_every_module():
    design = _text("docs/design.md")
    start = design.index("## Module map")
    end = design.find("\n## ", start + 1)
    section = design[start:] if end < 0 else design[start:end]
    package = REPO_ROOT / "dlo_course"
    missing = [p.name for p in sorted(package.glob("*.py")) if f"`{p.name}`" not in section]
    grading = package / "grading"
    missing += [f"grading/{p.stem}" for p in sorted(grading.glob("*.py"))
                if p.stem != "__init__" and f"`{p.stem}`" not in section]
    assert not missing, f"docs/design.md, 'Module map' does not name {missing}"
