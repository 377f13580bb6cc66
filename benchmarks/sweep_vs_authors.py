"""Our sweep against the authors' files, record by record and level by level (issue 35).

    # a committed database against the authors' file of its box:
    python benchmarks/sweep_vs_authors.py --database small
    # record a sweep now (the first 155 records: the small box's first level), in the default
    # scene or in one with other SimParams fields, e.g. another mesh or the old dampers:
    python benchmarks/sweep_vs_authors.py --box small --record --limit 155 \
        [--params '{"edge_damping": 1.0}'] [--node-ids 53,129,101,179]

Prints a Markdown table (mean, median and maximum of the per-record mean node distance, per
level and over all) and appends it, with the command, to ``--out`` when given. ``--node-ids``
names the 4 nodes of a mesh whose numbering is not the course's (rings 26, 23, 18, 15 on the
+x side).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from dlo_course.bench import publish
from dlo_course.database import BOXES, generate_database, load_database
from dlo_course.fidelity import compare_with_authors, fidelity_markdown
from dlo_course.mesh import selected_nodes
from dlo_course.simulation import sim_params


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--database", help="a database name or .npz path to compare")
    parser.add_argument("--box", choices=sorted(BOXES), help="the box (default: the database's)")
    parser.add_argument("--record", action="store_true", help="record the sweep now")
    parser.add_argument("--limit", type=int, default=None, help="records to make (--record)")
    parser.add_argument("--params", default="{}", help="SimParams fields as JSON (--record)")
    parser.add_argument("--node-ids", default=None,
                        help="comma-separated ids of the 4 nodes (default: selected_nodes(4))")
    parser.add_argument("--out", type=Path, default=None, help="append the result here")
    args = parser.parse_args()
    if args.record == bool(args.database):
        parser.error("give either --database or --record")

    start = time.perf_counter()
    if args.record:
        if args.box is None:
            parser.error("--record needs --box")
        params = sim_params(json.loads(args.params))
        with tempfile.TemporaryDirectory() as tmp:
            path = generate_database(args.box, out=Path(tmp) / "sweep.npz", limit=args.limit,
                                     params=params)
            db = load_database(path)
        box, label = args.box, f"recorded now ({len(db)} records), params {args.params}"
    else:
        db = load_database(args.database)
        box, label = args.box or db.box, f"database {db.name!r} ({len(db)} records)"
    ids = ([int(i) for i in args.node_ids.split(",")] if args.node_ids
           else list(selected_nodes(4)))
    rows = compare_with_authors(db.nodes[:, ids].astype(np.float64), box)
    seconds = time.perf_counter() - start
    publish([f"{label} against the authors' {box} file, 4 nodes, per-record mean node "
             f"distance ({seconds:.0f} s):", "", fidelity_markdown(rows)], args.out)

if __name__ == "__main__":
    main()
