"""Helpers for the lesson notebooks: how long to run, and where to write.

Every lesson imports these two, and nothing else of the grading machinery: ``from
dlo_course.notebook import fast_mode, output_dir``. (``dlo_course.course`` re-exports them for
notebooks written before this module existed.) Exercise cells may use them too: they hold no
answer.
"""

from __future__ import annotations

import os
from pathlib import Path

from dlo_course.paths import REPO_ROOT


def fast_mode() -> bool:
    """True when ``DLO_COURSE_FAST`` is set (to anything but "", "0", "false", "no"):
    notebooks then shrink episodes, steps and training runs to a few seconds."""
    return os.environ.get("DLO_COURSE_FAST", "").strip().lower() not in ("", "0", "false", "no")


def output_dir(*parts: str) -> Path:
    """Where notebooks write pictures, GIFs and runs: ``$DLO_COURSE_OUTPUT`` or, by default,
    ``reports/lessons`` in the repository (ignored by git). Created if missing.

    Args:
        parts: sub-folders, e.g. ``output_dir("04", "pendulum")``.
    """
    base = Path(os.environ.get("DLO_COURSE_OUTPUT", REPO_ROOT / "reports" / "lessons"))
    path = base.joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path
