"""What reading the tip with forward kinematics between steps changes in the environment.

    python benchmarks/tip_reads.py [--actions 60] [--seeds 0 1 2] [--out FILE]

The course reads the tip as the last physics step left it (``getLinkState`` without
``computeForwardKinematics``), as the authors did; until issue 35 it forced forward kinematics
at every read. Two scenes take the same seeded random actions through the environment's path
(``tip_target`` then ``move_tip_to``), one reading as today and one forcing forward kinematics;
after every action this prints how far apart their 200 nodes and their tips are, and at the end
how the tip velocity that the observation reports differs between the two reads of one state.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dlo_course.bench import publish
from dlo_course.simulation import RodScene, p


class ForwardKinematicsScene(RodScene):
    """The scene as it read the tip before issue 35: forward kinematics at every read."""

    def _tip_link_state(self, velocity: bool = False) -> tuple:
        return p.getLinkState(self.panda, self.params.tip_link, computeLinkVelocity=int(velocity),
                              computeForwardKinematics=1, physicsClientId=self.client)


def run(seed: int, actions: int) -> dict:
    moves = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(actions, 3))
    scenes = [RodScene(), ForwardKinematicsScene()]
    node_gap, tip_gap = [], []
    try:
        for a in moves:
            for scene in scenes:
                scene.move_tip_to(scene.tip_target(a))
            nodes = [s.node_positions() for s in scenes]
            node_gap.append(np.linalg.norm(nodes[0] - nodes[1], axis=1))
            tip_gap.append(np.linalg.norm(scenes[0].tip_position() - scenes[1].tip_position()))
        plain = scenes[0].tip_state()  # the same state read both ways, last (FK changes it)
        forced = ForwardKinematicsScene._tip_link_state(scenes[0], velocity=True)
    finally:
        for scene in scenes:
            scene.close()
    node_gap, tip_gap = np.array(node_gap), np.array(tip_gap)
    return {"node_mean_mm": 1e3 * node_gap.mean(axis=1), "node_max_mm": 1e3 * node_gap.max(),
            "tip_max_mm": 1e3 * tip_gap.max(),
            "velocity_gap": float(np.linalg.norm(plain[1] - np.array(forced[6]))),
            "speed": float(np.linalg.norm(plain[1]))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actions", type=int, default=60)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    lines = [
             "| seed | mean node gap after 10 / 30 / all actions (mm) | largest node gap (mm) | "
             "largest tip gap (mm) | tip velocity at the end: norm of plain minus FK read, of the speed (m/s) |",
             "|---|---|---|---|---|"]
    for seed in args.seeds:
        r = run(seed, args.actions)
        m = r["node_mean_mm"]
        lines.append(f"| {seed} | {m[min(9, len(m) - 1)]:.2f} / {m[min(29, len(m) - 1)]:.2f} / "
                     f"{m[-1]:.2f} | {r['node_max_mm']:.2f} | {r['tip_max_mm']:.2f} | "
                     f"{r['velocity_gap']:.4f} of {r['speed']:.3f} |")
    publish(lines, args.out)


if __name__ == "__main__":
    main()
