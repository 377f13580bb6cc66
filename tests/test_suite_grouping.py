"""The README's test command distributes with ``--dist loadgroup``: tests that share an
expensive session fixture (tests/conftest.py, ``SHARED_ON_ONE_WORKER``) or module state
(``xdist_group`` marks) must land on one worker. pytest 9.2 with pytest-xdist 3.8 silently
stopped grouping (xdist writes the node id field that pytest 9.2 no longer reads:
pytest-dev/pytest-xdist#1386), so constraints.txt pins pytest below 9.2; this test fails
wherever grouping is lost again."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

TWO_GROUPED = """
import pytest

@pytest.mark.xdist_group("shared")
def test_a():
    pass

@pytest.mark.xdist_group("shared")
def test_b():
    pass

def test_c():
    pass

def test_d():
    pass
"""


def test_loadgroup_sends_a_group_to_one_worker(tmp_path):
    pytest.importorskip("xdist")
    (tmp_path / "test_grouped.py").write_text(TWO_GROUPED)
    done = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "--dist", "loadgroup",
                           "-v", "-p", "no:cacheprovider", "test_grouped.py"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    workers = {name: worker for worker, name in
               re.findall(r"\[(gw\d)\].*PASSED test_grouped\.py::(test_\w+)", done.stdout)}
    assert set(workers) == {"test_a", "test_b", "test_c", "test_d"}, done.stdout
    assert "test_a@shared" in done.stdout, f"the group was dropped:\n{done.stdout}"
    assert workers["test_a"] == workers["test_b"], done.stdout
