"""``dlo-course bench scene``: the course's scene against a bare scene with the authors' settings.

All scenes run in one process, in interleaved blocks of the same random tip moves: these
machines are shared, so only rates measured side by side, as ratios, mean anything.

:class:`AuthorsScene` is a bare PyBullet world written from FACTS.md ("Simulation", "Scene in
the code"): plane, a table (a box), the Panda at (0.7, 0, 1.435) in its initial joints, the rod
loaded with the course's material, node 0 anchored to the ground and node 1 to link 7, PyBullet's
default IK from the current tip with the current orientation, position control at 2400 N m, one
``stepSimulation()`` of 20 sub-steps of 0.15 ms per action. Its :class:`Switches` add the
course's differences one at a time, so that a table shows what each one costs and whether it
changes the physics (the largest node distance to the course's scene after the same moves).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dlo_course.simulation import (
    RodScene, SimParams, edge_spring_args, ensure_mesh, nullspace_ik_args, p, pybullet_data,
    quiet_c_stdout)

GRIPPER_LINKS = RodScene.GRIPPER_LINKS


@dataclass(frozen=True)
class Switches:
    """How an :class:`AuthorsScene` differs from the authors' settings (all off = theirs)."""

    filter_gripper: bool = False
    """No contact between the gripper links 7-11 and the rod (the course's grasp)."""
    filter_plane: bool = False
    """No contact between the plane and the rod (the course's ground fixation)."""
    pedestal: bool = False
    """The course's visual-only pedestal multibody under the robot."""
    nullspace_ik: bool = False
    """The course's IK: rest poses and joint limits (null space), 50 iterations, 1e-5."""
    hold_orientation: bool = False
    """IK to the initial tip orientation instead of the current one."""
    params_first: bool = False
    """``setTimeStep`` / ``numSubSteps`` before loading the bodies instead of after."""
    motors_before_rod: bool = False
    """Set the initial joint targets before ``loadSoftBody`` instead of after."""
    spring_args: bool = True
    """Pass the edge-spring arguments to ``loadSoftBody`` (:func:`edge_spring_args`). Without
    them the rod gets whatever the command buffer holds: hidden edge dampers after
    ``setJointMotorControlArray`` (``motors_before_rod``), as RodScene had before issue 10."""
    edge_damping: float = 0.0
    """Edge dampers (N s/m) when ``spring_args``; the course's default is 0 (it was 1.0)."""
    self_collision: bool = True
    """Rod self-collision (on in the authors' code and the course)."""
    filter_arm: bool = False
    """Also no contact between the arm links -1..6 and the rod (a knob, not a difference)."""
    engine: tuple[tuple[str, float], ...] = ()
    """Extra ``setPhysicsEngineParameter`` settings applied after the build (knobs)."""


AUTHORS = Switches()
"""The authors' settings as FACTS.md gives them: no collision filter."""
AUTHORS_STABLE = Switches(filter_plane=True)
"""The authors' settings with the rod-plane contact off: with this course's mesh, whose bottom
ring lies on the plane, that contact makes the rod explode within 7-18 random moves (measured,
seeds 0-3), after which a step costs 5-80 times as much and a rate means nothing."""
COURSE = Switches(filter_gripper=True, filter_plane=True, pedestal=True, nullspace_ik=True,
                  hold_orientation=True, params_first=True, motors_before_rod=True,
                  edge_damping=SimParams().edge_damping)
"""Every difference on: the same world as :class:`RodScene` (checked by the benchmark)."""


def exploded(nodes: np.ndarray) -> bool:
    """True for node positions that are not finite or absurdly far away (a blown-up rod)."""
    return bool(not np.all(np.isfinite(nodes)) or np.abs(nodes).max() > 10.0
                or nodes[:, 2].min() < -0.5)


class AuthorsScene:
    """A bare PyBullet world with the authors' settings, plus the course's ``switches``."""

    def __init__(self, switches: Switches = AUTHORS, params: SimParams | None = None) -> None:
        self.switches = switches
        self.params = params or SimParams()
        with quiet_c_stdout():
            self.client = p.connect(p.DIRECT)
        self._build()

    def _build(self) -> None:
        c, prm, sw = self.client, self.params, self.switches
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=c)
        p.setGravity(0, 0, prm.gravity, physicsClientId=c)
        if sw.params_first:
            self._set_time()
        data = Path(pybullet_data.getDataPath())
        self.plane = p.loadURDF(str(data / "plane.urdf"), physicsClientId=c)
        height = prm.panda_base[2]
        table = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.2, 0.3, height / 2],
                                       physicsClientId=c)
        p.createMultiBody(0.0, table, -1, [prm.panda_base[0], prm.panda_base[1], height / 2],
                          physicsClientId=c)
        self.panda = p.loadURDF(str(data / "franka_panda" / "panda.urdf"), list(prm.panda_base),
                                useFixedBase=True, physicsClientId=c)
        for joint, q in enumerate(prm.initial_joints):
            p.resetJointState(self.panda, joint, q, physicsClientId=c)
        self.stepped = False
        tip, self.initial_orientation = self._tip()
        low, high = np.asarray(prm.workspace_low), np.asarray(prm.workspace_high)
        self.workspace = (tip + low, tip + high)
        if sw.motors_before_rod:
            self._set_targets(prm.initial_joints)

        mu, lam = prm.lame
        springs = edge_spring_args(sw.edge_damping) if sw.spring_args else {}
        with quiet_c_stdout():
            self.rod = p.loadSoftBody(
                str(ensure_mesh(prm)), basePosition=[tip[0], tip[1], 0.0], scale=1.0,
                mass=prm.mass, useNeoHookean=1, NeoHookeanMu=mu, NeoHookeanLambda=lam,
                NeoHookeanDamping=prm.damping, useSelfCollision=int(sw.self_collision),
                frictionCoeff=prm.friction, collisionMargin=prm.collision_margin,
                physicsClientId=c, **springs)
        if sw.pedestal:
            box = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.15, 0.15, height / 2],
                                      physicsClientId=c)
            p.createMultiBody(0.0, -1, box, [prm.panda_base[0], prm.panda_base[1], height / 2],
                              physicsClientId=c)
        p.createSoftBodyAnchor(self.rod, 0, -1, -1, physicsClientId=c)
        p.createSoftBodyAnchor(self.rod, 1, self.panda, prm.tip_link, physicsClientId=c)
        filtered = (GRIPPER_LINKS if sw.filter_gripper else ()) + \
            (tuple(range(-1, 7)) if sw.filter_arm else ())
        for link in filtered:
            p.setCollisionFilterPair(self.panda, self.rod, link, -1, 0, physicsClientId=c)
        if sw.filter_plane:
            p.setCollisionFilterPair(self.plane, self.rod, -1, -1, 0, physicsClientId=c)
        if not sw.params_first:
            self._set_time()
        if not sw.motors_before_rod:
            self._set_targets(prm.initial_joints)
        for name, value in sw.engine:
            p.setPhysicsEngineParameter(**{name: value}, physicsClientId=c)

        self.ik_args: dict = {}
        if sw.nullspace_ik:
            self.ik_args = dict(nullspace_ik_args(self.panda, prm.initial_joints, c),
                                maxNumIterations=50, residualThreshold=1e-5)

    def _set_time(self) -> None:
        p.setTimeStep(self.params.time_step, physicsClientId=self.client)
        p.setPhysicsEngineParameter(numSubSteps=self.params.sub_steps,
                                    physicsClientId=self.client)

    def _set_targets(self, joints) -> None:
        p.setJointMotorControlArray(self.panda, list(range(7)), p.POSITION_CONTROL,
                                    targetPositions=list(joints),
                                    forces=[self.params.joint_force] * 7,
                                    physicsClientId=self.client)

    def _tip(self) -> tuple[np.ndarray, tuple]:
        # As the authors read it: the link state the last step left (forward kinematics only
        # before the first step, after resetJointState).
        state = p.getLinkState(self.panda, self.params.tip_link,
                               computeForwardKinematics=int(not self.stepped),
                               physicsClientId=self.client)
        return np.array(state[4]), state[5]

    def act(self, action: np.ndarray) -> None:
        """One action: tip target by IK, joint targets, one ``stepSimulation()``."""
        prm = self.params
        tip, orientation = self._tip()
        target = np.clip(tip + np.asarray(action) * prm.v_max * prm.action_duration,
                         *self.workspace)
        if self.switches.hold_orientation:
            orientation = self.initial_orientation
        joints = p.calculateInverseKinematics(self.panda, prm.tip_link, list(target),
                                              orientation, physicsClientId=self.client,
                                              **self.ik_args)
        self._set_targets(joints[:7])
        p.stepSimulation(physicsClientId=self.client)
        self.stepped = True

    def nodes(self) -> np.ndarray:
        _, vertices = p.getMeshData(self.rod, -1, flags=p.MESH_DATA_SIMULATION_MESH,
                                    physicsClientId=self.client)
        return np.asarray(vertices, dtype=np.float64)

    def close(self) -> None:
        p.disconnect(physicsClientId=self.client)


class CourseScene:
    """:class:`RodScene` as the benchmark drives it: ``env.step``'s path without the env."""

    def __init__(self, params: SimParams | None = None) -> None:
        self.scene = RodScene(params)

    def act(self, action: np.ndarray) -> None:
        self.scene.move_tip_to(self.scene.tip_target(action))

    def nodes(self) -> np.ndarray:
        return self.scene.node_positions()

    def close(self) -> None:
        self.scene.close()


@dataclass
class RaceResult:
    """One scene's share of a race."""

    name: str
    actions: int = 0
    seconds: float = 0.0
    max_deviation: float = 0.0
    """Largest node distance (m) to the reference scene at the ends of blocks."""
    exploded_at: int | None = None

    @property
    def actions_per_s(self) -> float:
        return self.actions / self.seconds if self.seconds > 0 else float("nan")


def race(scenes: dict, actions: np.ndarray, block: int = 10) -> list[RaceResult]:
    """Run every scene through ``actions`` in interleaved blocks; the first is the reference.

    The order of the scenes rotates from block to block, so that none always runs first after
    the others. A scene that blows up is dropped (its rate is over the actions it ran).
    """
    names = list(scenes)
    results = {name: RaceResult(name) for name in names}
    alive = list(names)
    for b, start in enumerate(range(0, len(actions), block)):
        chunk = actions[start:start + block]
        order = alive[b % len(alive):] + alive[:b % len(alive)]
        for name in order:
            scene, r = scenes[name], results[name]
            t = time.perf_counter()
            for a in chunk:
                scene.act(a)
            dt = time.perf_counter() - t
            r.seconds += dt
            r.actions += len(chunk)
        reference = scenes[names[0]].nodes() if names[0] in alive else None
        for name in list(alive):
            nodes = scenes[name].nodes()
            if exploded(nodes):
                results[name].exploded_at = start + len(chunk)
                alive.remove(name)
            elif reference is not None:
                gap = float(np.linalg.norm(nodes - reference, axis=1).max())
                results[name].max_deviation = max(results[name].max_deviation, gap)
    return [results[name] for name in names]


def scene_rows(switch_table: bool = False, knob_table: bool = False,
               plane_contact: bool = False) -> dict[str, object]:
    """Name -> scene factory of the rows to race; the course's RodScene comes first."""
    authors = AUTHORS if plane_contact else AUTHORS_STABLE
    authors_name = ("authors' settings (all contacts on)" if plane_contact
                    else "authors' settings (rod-plane contact off)")
    rows: dict[str, object] = {
        "course: RodScene (no dampers)": lambda: CourseScene(),
        "course, edge_damping=1 (the old dampers)":
            lambda: CourseScene(SimParams(edge_damping=1.0)),
    }
    if switch_table:
        without = {"gripper filter": "filter_gripper", "plane filter": "filter_plane",
                   "pedestal": "pedestal", "null-space IK": "nullspace_ik",
                   "held orientation": "hold_orientation",
                   "engine params before loading": "params_first",
                   "motor targets before rod": "motors_before_rod"}
        rows["model: AuthorsScene + all switches"] = lambda: AuthorsScene(COURSE)
        rows["course before issue 10 (hidden dampers)"] = \
            lambda: AuthorsScene(replace(COURSE, spring_args=False))
        for label, name in without.items():
            rows[f"course without {label}"] = \
                lambda name=name: AuthorsScene(replace(COURSE, **{name: False}))
        rows["authors + hidden dampers only"] = \
            lambda: AuthorsScene(replace(authors, motors_before_rod=True, spring_args=False))
    if knob_table:
        knobs = {"no rod self-collision": dict(self_collision=False),
                 "arm links -1..6 filtered too": dict(filter_arm=True),
                 "numSolverIterations=10": dict(engine=(("numSolverIterations", 10),)),
                 "solverResidualThreshold=1e-4": dict(engine=(("solverResidualThreshold", 1e-4),)),
                 "sparseSdfVoxelSize=0.5": dict(engine=(("sparseSdfVoxelSize", 0.5),)),
                 "deterministicOverlappingPairs=0":
                     dict(engine=(("deterministicOverlappingPairs", 0),)),
                 "numNonContactInnerIterations=2":
                     dict(engine=(("numNonContactInnerIterations", 2),))}
        for label, change in knobs.items():
            rows[f"course, {label}"] = lambda change=change: AuthorsScene(replace(COURSE, **change))
    rows[authors_name] = lambda: AuthorsScene(authors)
    return rows


def bench_scene(actions: int = 60, block: int = 10, seed: int = 0, switch_table: bool = False,
                knob_table: bool = False, plane_contact: bool = False) -> list[RaceResult]:
    """Race the scenes on the same seeded random actions and print a table of ratios."""
    factories = scene_rows(switch_table, knob_table, plane_contact)
    scenes = {name: make() for name, make in factories.items()}
    moves = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(actions, 3))
    try:
        results = race(scenes, moves, block)
    finally:
        for scene in scenes.values():
            scene.close()
    authors = results[-1]
    print(f"{len(scenes)} scenes, {actions} random moves (seed {seed}) in blocks of {block}, "
          "one process, interleaved")
    print(f"{'scene':<44} {'actions/s':>9} {'x authors':>9} {'x course':>8} "
          f"{'node gap to course':>19}")
    for r in results:
        note = f"  exploded by action {r.exploded_at}" if r.exploded_at is not None else ""
        print(f"{r.name:<44} {r.actions_per_s:>9.2f} "
              f"{r.actions_per_s / authors.actions_per_s:>9.2f} "
              f"{r.actions_per_s / results[0].actions_per_s:>8.2f} "
              f"{r.max_deviation * 1e3:>16.1f} mm{note}")
    return results


def record_trajectory(params: SimParams | None = None, n_actions: int = 60,
                      seed: int = 12345, moves: np.ndarray | None = None) -> np.ndarray:
    """All 200 node positions (n_actions + 1, 200, 3) over seeded random actions in [-1, 1]^3
    (or over ``moves`` (K, 3), given).

    Through :class:`RodScene` exactly as ``DLOShapeEnv.step`` drives it (tip target, IK, one
    action of physics), from the freshly built scene: the check that a speed change leaves
    the physics alone.
    """
    if moves is None:
        moves = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n_actions, 3))
    scene = RodScene(params)
    try:
        trajectory = [scene.node_positions()]
        for a in moves:
            scene.move_tip_to(scene.tip_target(a))
            trajectory.append(scene.node_positions())
    finally:
        scene.close()
    return np.array(trajectory)
