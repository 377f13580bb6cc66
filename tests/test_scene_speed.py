"""Issue 10: the rod must not depend on the PyBullet commands sent before it was loaded.

PyBullet 3.2.7 takes a soft body's spring constants from its shared command buffer even when
no mass-spring force is asked for. RodScene set the arm's joint targets just before loading the
rod, so every rod silently got edge springs and dampers of 1.0 (the default joint gain of
``setJointMotorControlArray``): about a third of a step's time, and physics. RodScene now
passes the spring arguments itself (``SimParams.edge_damping``). These tests poison the buffer
before ``loadSoftBody`` and check that the rod moves exactly as without the poison, and that
the benchmark's model of the course's scene is RodScene's world. Nothing is timed.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dlo_course import simulation
from dlo_course.scene_bench import COURSE, AuthorsScene, CourseScene
from dlo_course.simulation import SimParams, edge_spring_args, p

MOVES = np.array([[1.0, -0.5, -0.8], [-0.7, 1.0, 0.3], [0.2, -1.0, -1.0]])


def nodes_after_moves(scene) -> np.ndarray:
    try:
        for a in MOVES:
            scene.act(a)
        return scene.nodes()
    finally:
        scene.close()


def poison_command_buffer(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make every ``loadSoftBody`` follow a joint-motor command with unusual gains (5.0), as a
    stray command before the rod would. The first action's command resets the gains before
    any physics step, so only what the rod reads from the buffer can differ."""
    load = p.loadSoftBody

    def poisoned(*args, **kwargs):
        client = kwargs["physicsClientId"]
        for i in range(p.getNumBodies(physicsClientId=client)):
            body = p.getBodyUniqueId(i, physicsClientId=client)
            if p.getBodyInfo(body, physicsClientId=client)[1] == b"panda":
                joints = [s[0] for s in p.getJointStates(body, range(7), physicsClientId=client)]
                p.setJointMotorControlArray(body, list(range(7)), p.POSITION_CONTROL,
                                            targetPositions=joints, positionGains=[5.0] * 7,
                                            velocityGains=[5.0] * 7, physicsClientId=client)
        return load(*args, **kwargs)

    monkeypatch.setattr(simulation.p, "loadSoftBody", poisoned)


@pytest.mark.parametrize("edge_damping", [1.0, 0.0])
def test_rod_ignores_the_command_buffer(edge_damping, monkeypatch):
    params = SimParams(edge_damping=edge_damping)
    before_issue_10 = replace(COURSE, spring_args=False)  # RodScene's old loadSoftBody call
    clean = nodes_after_moves(CourseScene(params))
    old_clean = nodes_after_moves(AuthorsScene(before_issue_10))
    with monkeypatch.context() as m:
        poison_command_buffer(m)
        poisoned = nodes_after_moves(CourseScene(params))
        old_poisoned = nodes_after_moves(AuthorsScene(before_issue_10))
    if np.array_equal(old_clean, old_poisoned):
        pytest.skip("this PyBullet does not read stale spring constants: nothing to guard")
    np.testing.assert_array_equal(poisoned, clean)


def test_benchmark_model_is_rodscene():
    """AuthorsScene with every course switch on builds RodScene's world, to the bit."""
    np.testing.assert_array_equal(nodes_after_moves(AuthorsScene(COURSE)),
                                  nodes_after_moves(CourseScene()))


def test_edge_spring_arguments():
    assert COURSE.edge_damping == SimParams().edge_damping == 0.0  # the authors' rod has none
    damped = edge_spring_args(1.0)
    assert damped["useMassSpring"] == 1 and damped["springDampingStiffness"] == 1.0
    assert damped["springElasticStiffness"] > 0  # PyBullet adds no force without stiffness
    plain = edge_spring_args(0.0)
    # Still written, as zeros, so that nothing stale is read; zero stiffness adds no force.
    assert plain["springElasticStiffness"] == plain["springDampingStiffness"] == 0.0
    assert damped["springBendingStiffness"] == plain["springBendingStiffness"] == 0.0
    with pytest.raises(ValueError):
        SimParams(edge_damping=-1.0)
