"""`dlo-course train`, plus every rank's network digests (lesson 8, section 6).

    mpiexec -n 32 python scripts/train_with_digests.py --preset smoke --out RUN [train options]

Runs exactly ``dlo-course train`` with the same options, and also writes ``RUN/digests.json``:
at every resume state the trainer checks that all ranks hold bit-identical networks
(``dlo_course.mpi.modules_in_sync``, called on every rank); here that check also gathers each
rank's digest of its actor and critic (``dlo_course.mpi.module_digest``, a hash of the exact
bytes of the weights), so the lesson can show them rank by rank. ``--out`` is required.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from dlo_course import mpi
from dlo_course.cli import main

checked_in_sync = mpi.modules_in_sync
checkpoints: list[list[list[str]]] = []  # per resume state: per rank: [actor, critic] digests


def in_sync_and_recorded(*modules):
    """The trainer's check, after gathering every rank's digests (a collective: every rank
    calls it at the same point, as the trainer does)."""
    checkpoints.append(mpi.allgather([mpi.module_digest(m) for m in modules[:2]]))
    return checked_in_sync(*modules)


if __name__ == "__main__":
    args = sys.argv[1:]
    if "--out" not in args:
        sys.exit("usage: train_with_digests.py --out RUN [dlo-course train options]")
    out = Path(args[args.index("--out") + 1])
    mpi.modules_in_sync = in_sync_and_recorded  # the trainer calls mpi.modules_in_sync(...)
    main(["train", *args], standalone_mode=False)
    if mpi.is_root():
        (out / "digests.json").write_text(json.dumps(
            {"ranks": mpi.size(), "networks": ["actor", "critic"],
             "checkpoints": checkpoints}, indent=1) + "\n")
