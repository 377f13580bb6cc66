"""Benchmark (not a test): the course's scene against a minimal scene with the authors' settings.

Issue 10. Every scene runs in this one process, in interleaved blocks of the same random tip
moves, and the table gives actions per second and ratios (these machines are shared: read the
ratios). Then the switch table (the course's differences switched off one at a time) and the
knob table (PyBullet settings tried on the course's scene), each with the largest node
distance to the course's scene after the same moves: a knob that moves nodes changes physics.
Last, the physics check: all 200 nodes over a fixed 60-action sequence through RodScene,
against a saved reference trajectory and against the rod without edge dampers.

    python benchmarks/scene_speed.py [--actions 200] [--table-actions 60]
        [--reference traj.npy] [--save-reference traj.npy] [--out results.txt]

The same race, without the tables and the physics check: ``dlo-course bench scene``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from dlo_course.scene_bench import bench_scene, record_trajectory
from dlo_course.simulation import SimParams


def physics_check(reference: Path | None, save: Path | None) -> None:
    """Largest node distance (mm) of today's RodScene to a reference, and to no dampers."""
    trajectory = record_trajectory()
    if save is not None:
        np.save(save, trajectory)
        print(f"saved the 60-action trajectory {trajectory.shape} to {save}")
    if reference is not None:
        gap = np.linalg.norm(trajectory - np.load(reference), axis=-1)
        print(f"RodScene vs {reference}: largest node distance {gap.max() * 1e3:.4f} mm "
              f"(mean {gap.mean() * 1e3:.4f} mm), all 200 nodes, 61 snapshots")
    plain = record_trajectory(SimParams(edge_damping=0.0))
    gap = np.linalg.norm(trajectory - plain, axis=-1)
    print(f"edge_damping=0 vs the default 1.0: largest node distance {gap.max() * 1e3:.1f} mm "
          f"(mean {gap.mean() * 1e3:.1f} mm): the dampers are physics, not overhead")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actions", type=int, default=200,
                        help="moves per scene in the main race (default 200)")
    parser.add_argument("--table-actions", type=int, default=60,
                        help="moves per scene in the switch and knob tables (default 60)")
    parser.add_argument("--block", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--reference", type=Path, default=None,
                        help="a saved 60-action trajectory (.npy) to compare RodScene with")
    parser.add_argument("--save-reference", type=Path, default=None,
                        help="save today's 60-action trajectory (.npy) here")
    parser.add_argument("--out", type=Path, default=None, help="also write the output here")
    args = parser.parse_args()

    buffer = io.StringIO()

    class Tee(io.TextIOBase):
        def write(self, text: str) -> int:
            sys.__stdout__.write(text)
            sys.__stdout__.flush()
            return buffer.write(text)

    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    with contextlib.redirect_stdout(Tee()):
        print(time.strftime("%a %b %d %H:%M:%S UTC %Y", time.gmtime()))
        print(f"$ {command}\n")
        print("== main race ==")
        bench_scene(actions=args.actions, block=args.block, seed=args.seed)
        print("\n== switch table: the course's differences, one at a time ==")
        bench_scene(actions=args.table_actions, block=args.block, seed=args.seed,
                    switch_table=True)
        print("\n== knob table: PyBullet settings on the course's scene ==")
        bench_scene(actions=args.table_actions, block=args.block, seed=args.seed,
                    knob_table=True)
        print("\n== physics check ==")
        physics_check(args.reference, args.save_reference)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(buffer.getvalue())


if __name__ == "__main__":
    main()
