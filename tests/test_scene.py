"""The scene's switches: how the rod is anchored, its contacts, its fingers, and SimParams from
JSON. The physics tests run a few real PyBullet moves each (a few seconds)."""

from __future__ import annotations

import numpy as np
import pytest

from dlo_course.scene_bench import record_trajectory
from dlo_course.simulation import AUTHORS_SETTINGS, RodScene, SimParams, sim_params

MOVES = np.array([[1.0, -0.5, -0.8], [-0.7, 1.0, 0.3], [0.2, -1.0, -1.0], [-1.0, 0.4, -1.0]])


def trajectory(params: SimParams, moves=MOVES) -> np.ndarray:
    """All node positions (len(moves) + 1, 200, 3) over ``moves``, from a fresh scene."""
    return record_trajectory(params, moves=moves)


def test_sim_params_from_a_dict():
    assert sim_params(None) == SimParams()
    params = sim_params({"edge_damping": 0.5, "workspace_low": [-0.1, -0.2, -0.3]})
    assert params.edge_damping == 0.5 and params.workspace_low == (-0.1, -0.2, -0.3)
    assert sim_params(params) is params
    with pytest.raises(ValueError, match="unknown SimParams field.*bogus"):
        sim_params({"bogus": 1})
    with pytest.raises(TypeError):
        sim_params(3)
    authors = sim_params(AUTHORS_SETTINGS)
    # No dampers and no ground contact, as the default; the rest moves the sweep < 0.1 mm.
    assert authors.edge_damping == SimParams().edge_damping == 0.0
    assert authors.plane_contact is SimParams().plane_contact is False


@pytest.mark.parametrize("field, value", [("anchors", "glue"), ("finger_opening", 0.2),
                                          ("finger_opening", -0.01), ("edge_damping", -1.0)])
def test_bad_scene_switches_are_refused(field, value):
    with pytest.raises(ValueError, match=field):
        SimParams(**{field: value})


def test_the_environment_takes_params_as_json():
    from dlo_course.env import make_env

    env = make_env(params={"edge_damping": 0.0, "plane_contact": False})
    try:
        assert env.unwrapped.params.edge_damping == 0.0
        assert env.unwrapped.scene.params.plane_contact is False
    finally:
        env.close()


@pytest.mark.slow
def test_anchors_hold_the_rod_ends_where_the_authors_put_them():
    """Node 0 stays at (tip_x, tip_y, 0) and node 1 at the flange's load-time offset. The
    authors' link-frame pivot (0, 0, -(tip_z - length)) is ignored by PyBullet 3.2.7's
    deformable anchors (measured: bit for bit the same as no pivot), so node 1 keeps the
    8 cm below the flange that it had when the rod was loaded."""
    scene = RodScene(SimParams(anchors="authors"))
    try:
        tip0 = scene.initial_tip.copy()
        scene.step_physics(3)
        for a in MOVES:
            scene.move_tip_to(scene.tip_target(a))
        scene.step_physics(40)  # the arm reaches its last target
        nodes, tip = scene.node_positions(), scene.tip_position()
    finally:
        scene.close()
    np.testing.assert_allclose(nodes[0], [tip0[0], tip0[1], 0.0], atol=2e-3)
    below = tip0[2] - SimParams().length  # 8.1 cm: node 1 in the flange's frame, downwards
    np.testing.assert_allclose(nodes[1], tip - [0.0, 0.0, below], atol=5e-3)


@pytest.mark.slow
def test_both_anchorings_are_the_same_rod_without_plane_contact():
    """Anchoring node 0 to the plane body (the authors') or to the world (node mass 0) moves
    the rod the same, to a tenth of a millimetre, while the rod cannot touch the plane."""
    common = dict(plane_contact=False)
    gap = np.linalg.norm(trajectory(SimParams(anchors="authors", **common))
                         - trajectory(SimParams(anchors="nodes", **common)), axis=-1)
    assert gap.max() < 1e-4


@pytest.mark.slow
def test_plane_contact_is_stable_only_with_the_authors_anchor():
    """With node 0 anchored to the plane body the rod-plane contact stays sane over a fixed
    sequence of moves; anchored to the world (node mass 0) the same contact blows up."""
    moves = np.tile(MOVES, (3, 1))
    stable = trajectory(SimParams(anchors="authors", plane_contact=True), moves)
    assert np.all(np.isfinite(stable)) and stable[..., 2].min() > -0.01
    assert np.abs(stable - stable[0]).max() < 1.0  # no node flew off
    blown = trajectory(SimParams(anchors="nodes", plane_contact=True), moves)
    assert not np.all(np.isfinite(blown)) or np.abs(blown - blown[0]).max() > 1.0


@pytest.mark.slow
def test_dampers_change_the_rod():
    """The edge dampers are physics: the same moves end elsewhere with and without them."""
    moves = np.tile(MOVES, (3, 1))
    damped = trajectory(SimParams(edge_damping=1.0), moves)
    plain = trajectory(SimParams(edge_damping=0.0), moves)
    gap = np.linalg.norm(damped - plain, axis=-1).max()
    assert gap > 1e-3, f"{gap * 1e3:.3f} mm"


def test_the_tip_is_read_as_the_last_step_left_it():
    """As the authors read it: forward kinematics only before the first step after a build."""
    from dlo_course.simulation import p

    scene = RodScene()
    try:
        c, link = scene.client, scene.params.tip_link
        fresh = np.array(p.getLinkState(scene.panda, link, computeForwardKinematics=1,
                                        physicsClientId=c)[4])
        np.testing.assert_allclose(scene.tip_position(), fresh)
        np.testing.assert_allclose(scene.initial_tip, fresh)
        for _ in range(3):
            scene.move_tip_to(scene.tip_target(np.array([1.0, 0.5, 0.0])))
        stale = np.array(p.getLinkState(scene.panda, link, physicsClientId=c)[4])
        # Read first, before anything recomputes the links: a forward-kinematics read would
        # give the arm's present pose, about 0.5 mm away after these three moves.
        np.testing.assert_array_equal(scene.tip_position(), stale)
        np.testing.assert_array_equal(scene.tip_state()[0], stale)
        moved = np.array(p.getLinkState(scene.panda, link, computeForwardKinematics=1,
                                        physicsClientId=c)[4])
        assert np.linalg.norm(moved - stale) > 1e-5
    finally:
        scene.close()


def test_every_tip_target_is_clipped_to_the_workspace():
    scene = RodScene()
    try:
        low, high = scene.workspace
        assert high[2] == pytest.approx(scene.initial_tip[2])  # the top: the initial height
        above = scene.initial_tip + np.array([0.0, 0.7, 0.05])
        np.testing.assert_allclose(scene.clip_to_workspace(above),
                                   [scene.initial_tip[0], high[1], high[2]])
        np.testing.assert_allclose(scene.tip_target(np.ones(3)),
                                   np.minimum(scene.initial_tip + 0.06, high))
    finally:
        scene.close()
