"""Write the Colab and Binder links of the course from ``dlo_course.notebook``.

Run it from the repository root after changing ``REPOSITORY_URL`` (a fork) or the install
cell, then ``dlo-course course release`` to carry the cells into ``lessons/``:

    python binder/update_links.py && dlo-course course release

It rewrites two things, and is idempotent:

* in every ``solutions/NN_*.ipynb``, the Colab install cell, the first code cell, right
  after the lesson's title (``dlo_course.notebook.install_cell_source``);
* in ``lessons/README.md``, the table of "Open in Colab" and "Binder" badges between the
  ``<!-- badges: begin -->`` and ``<!-- badges: end -->`` lines.

``tests/test_notebook_install.py`` fails when either is out of date.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # runs from a checkout, installed or not

from dlo_course.grading.notebooks import notebooks_in, read_notebook, write_notebook
from dlo_course.notebook import binder_url, colab_url, install_cell_source  # noqa: E402

BADGES_BEGIN = "<!-- badges: begin -->"
BADGES_END = "<!-- badges: end -->"
COLAB_BADGE = "https://colab.research.google.com/assets/colab-badge.svg"
BINDER_BADGE = "https://mybinder.org/badge_logo.svg"


def install_cell(lesson: str) -> dict:
    """The install cell of the lesson numbered ``lesson`` ("01"...), as Jupyter stores it."""
    source = install_cell_source()
    return {"cell_type": "code", "execution_count": None, "id": f"{lesson}-colab",
            "metadata": {"tags": ["colab-install"]}, "outputs": [],
            "source": source.splitlines(keepends=True)}


def with_install_cell(nb: dict, lesson: str) -> dict:
    """``nb`` with exactly one install cell, at index 1 (after the title and goals)."""
    cell = install_cell(lesson)
    cells = [c for c in nb["cells"] if c.get("id") != cell["id"]]
    cells.insert(1, cell)
    return {**nb, "cells": cells}


def badge_table(notebooks: list[Path]) -> str:
    """The Markdown table of badges, one row per lesson."""
    rows = ["| lesson | Colab | Binder |", "|---|---|---|"]
    for path in notebooks:
        target = f"lessons/{path.name}"
        rows.append(f"| `{path.stem}` | [![Open In Colab]({COLAB_BADGE})]({colab_url(target)}) "
                    f"| [![Binder]({BINDER_BADGE})]({binder_url(target)}) |")
    return "\n".join(rows)


def with_badges(readme: str, notebooks: list[Path]) -> str:
    """``readme`` with the badge table between its markers replaced."""
    block = re.compile(re.escape(BADGES_BEGIN) + ".*?" + re.escape(BADGES_END), re.DOTALL)
    if not block.search(readme):
        raise SystemExit(f"lessons/README.md has no {BADGES_BEGIN} ... {BADGES_END} block")
    table = f"{BADGES_BEGIN}\n{badge_table(notebooks)}\n{BADGES_END}"
    return block.sub(lambda _: table, readme)


def main() -> None:
    notebooks = notebooks_in(ROOT / "solutions")
    for path in notebooks:
        nb = read_notebook(path)
        updated = with_install_cell(nb, path.name[:2])
        if updated != nb:
            write_notebook(updated, path)
            print(f"updated {path.relative_to(ROOT)}")
    readme = ROOT / "lessons" / "README.md"
    text = readme.read_text(encoding="utf-8")
    updated = with_badges(text, [ROOT / "lessons" / p.name for p in notebooks])
    if updated != text:
        readme.write_text(updated, encoding="utf-8")
        print(f"updated {readme.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
