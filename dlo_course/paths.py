"""Where the course keeps its files.

The data ships inside the repository (``data/``), next to the package. An installed copy
that is not a checkout can point elsewhere with the ``DLO_COURSE_DATA`` environment variable.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
DATA_DIR = Path(os.environ.get("DLO_COURSE_DATA", REPO_ROOT / "data"))
MESH_PATH = DATA_DIR / "rod.vtk"
DATABASE_DIR = DATA_DIR / "databases"
AGENTS_DIR = DATA_DIR / "checkpoints"
"""The shipped trained agents, one folder per node count (:func:`dlo_course.rundir.agent_dir`)."""
