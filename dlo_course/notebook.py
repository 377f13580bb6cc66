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


def markdown_tables(path: str | Path, raw: bool = False) -> list:
    """The tables of a Markdown file (a benchmark's or a report's ``README.md``), in order.
    Lessons quote measured numbers this way, so that they follow the file when a new
    measurement replaces it.

    Each table is a list of rows ``{column header: cell text}`` (cells stripped of spaces
    and of the backticks around code; a header repeated in one table gets " (2)", " (3)"...),
    or with ``raw=True`` its Markdown text, to display as it is. A table is a run of lines
    that start with ``|``, the second one being the ``|---|`` separator.
    """
    def cells(line: str) -> list[str]:
        return [c.strip().strip("`").strip() for c in line.strip().strip("|").split("|")]

    def unique(header: list[str]) -> list[str]:
        seen: dict[str, int] = {}
        names = []
        for name in header:
            seen[name] = seen.get(name, 0) + 1
            names.append(name if seen[name] == 1 else f"{name} ({seen[name]})")
        return names

    tables, block = [], []
    for line in [*Path(path).read_text(encoding="utf-8").splitlines(), ""]:
        if line.lstrip().startswith("|"):
            block.append(line)
            continue
        if len(block) >= 2 and set(block[1].replace("|", "").strip()) <= set("-: "):
            if raw:
                tables.append("\n".join(block))
            else:
                header = unique(cells(block[0]))
                tables.append([dict(zip(header, cells(row))) for row in block[2:]])
        block = []
    return tables
