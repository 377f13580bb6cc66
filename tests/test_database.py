import numpy as np
import pytest

from dlo_course import load_database
from dlo_course.database import BOXES, generate_database, save_database, sweep_waypoints


@pytest.mark.parametrize("name,count", [("small", 930), ("large", 2651)])
def test_sweep_count_and_extent(name, count):
    box = BOXES[name]
    waypoints = sweep_waypoints(box)
    assert len(waypoints) == box.expected_count == count
    np.testing.assert_allclose(waypoints[1:].min(axis=0), box.low, atol=1e-12)
    np.testing.assert_allclose(waypoints.max(axis=0)[:2], box.high[:2], atol=1e-12)
    # Snake order: apart from the start of the sweep, every move is at most one grid step.
    steps = box.size / (np.array(box.divisions) + 1)
    moves = np.abs(np.diff(waypoints[2:], axis=0))
    assert np.all(moves <= steps + 1e-12)


@pytest.mark.parametrize("name", ["small", "large"])
def test_shipped_databases(name):
    db = load_database(name)
    assert db.tip.shape == (BOXES[name].expected_count, 3)
    assert db.nodes.shape == (len(db.tip), 200, 3)
    assert bool(db.meta["complete"])
    for n in (2, 4, 6):
        assert db.goals(n).shape == (len(db), n, 3)
    # Every recorded tip is where the sweep sent it (the arm follows to a few mm).
    offsets = db.tip - db.meta["initial_tip"]
    assert np.max(np.abs(offsets - db.meta["offsets"])) < 0.01
    # The rod is held at both ends: node 0 on the ground, node 1 at the tip.
    np.testing.assert_allclose(db.nodes[:, 0, 2], 0.0, atol=0.005)
    assert np.max(np.linalg.norm(db.nodes[:, 1] - db.tip, axis=1)) < 0.1


def test_a_short_sweep_matches_its_waypoints(tmp_path):
    path = generate_database("small", out=tmp_path / "tiny.npz", limit=2, settle_steps=1,
                             progress=False)
    db = load_database(path)
    assert len(db) == 2 and not bool(db.meta["complete"])
    np.testing.assert_allclose(db.tip - db.meta["initial_tip"], sweep_waypoints(BOXES["small"])[:2],
                               atol=0.005)


def test_load_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown database"):
        load_database("medium")
    with pytest.raises(FileNotFoundError):
        load_database(tmp_path / "missing.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"not a zip file")
    with pytest.raises(ValueError, match="not a readable"):
        load_database(corrupt)
    no_nodes = tmp_path / "no_nodes.npz"
    np.savez(no_nodes, tip=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="no 'nodes'"):
        load_database(no_nodes)
    wrong = save_database(tmp_path / "wrong.npz", np.zeros((2, 3)), np.zeros((2, 100, 3)))
    with pytest.raises(ValueError, match="malformed"):
        load_database(wrong)
