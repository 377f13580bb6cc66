"""Helpers for the lesson notebooks: how long to run, and where to write.

Every lesson imports these two, and nothing else of the grading machinery: ``from
dlo_course.notebook import fast_mode, output_dir``. Exercise cells may use them too: they
hold no answer (:data:`dlo_course.grading.delegation.LIBRARY_HELPERS`).

Also here: what runs the lessons in the browser, the Colab install cell
(:func:`colab_install_command`, :func:`install_cell_source`) and the Colab and Binder links
(:func:`colab_url`, :func:`binder_url`), all from one address, :data:`REPOSITORY_URL`.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from urllib.parse import quote

from dlo_course.paths import REPO_ROOT

REPOSITORY_URL = "https://github.com/dlo-course/dlo-course"
"""The course's public repository, from which Colab installs it and Binder builds it. A
placeholder: a fork changes it here, then runs ``python binder/update_links.py`` (the
lessons' install cell and the badges of ``lessons/README.md``) and ``dlo-course course
release``, and edits the badge line of ``README.md`` by hand."""

REPOSITORY_BRANCH = "main"
"""The branch that Colab's and Binder's links open."""

COLAB_CHECKOUT = "/content/dlo-course"
"""Where the install cell clones the course in Colab (``/content`` is Colab's working
folder). A clone, not a plain ``pip install`` of the package: the data, the shipped agents
and the benchmarks' results the lessons read live in the repository, beside the package."""


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


# ------------------------------------------------------------------ Colab and Binder


def colab_install_command(modules=None) -> str | None:
    """The shell command that installs the course when a lesson runs in Google Colab, or
    None anywhere else (a local install or Binder already has it).

    Colab is recognised by its ``google.colab`` module. The command clones the repository
    (once: a second run of the cell keeps the clone) and installs it editable with the
    ``mpi`` extra, *without* ``constraints.txt``: its pin asks for the CPU build of torch,
    and Colab brings its own torch, which satisfies ``torch>=2.1``. Nor the ``notebooks``
    extra: Colab has its own Jupyter, which must not be upgraded under it.

    Args:
        modules: the loaded modules to look in (default ``sys.modules``; tests pass their own).
    """
    modules = sys.modules if modules is None else modules
    if "google.colab" not in modules:
        return None
    return (f"( [ -d {COLAB_CHECKOUT} ] || git clone --quiet --depth 1 --branch "
            f"{REPOSITORY_BRANCH} {REPOSITORY_URL} {COLAB_CHECKOUT} ) && "
            f"pip install --quiet -e '{COLAB_CHECKOUT}[mpi]'")


def install_cell_source() -> str:
    """The source of every lesson's first code cell: in Colab, run
    :func:`colab_install_command` and make the clone importable at once; elsewhere nothing.

    The cell cannot import this module (in Colab the course is not installed yet when it
    runs), so it carries the command as text; ``binder/update_links.py`` writes it into the
    notebooks and the tests check that they hold exactly this.
    """
    command = colab_install_command({"google.colab": None})
    return (
        "# Google Colab only: install the course (a minute or two). Elsewhere this does nothing.\n"
        "import sys\n"
        "\n"
        'if "google.colab" in sys.modules:\n'
        "    import subprocess\n"
        "\n"
        f"    subprocess.run({json.dumps(command)}, shell=True, check=True)\n"
        "    # pip's editable install is seen by a new kernel only; this one needs the path.\n"
        f"    sys.path.insert(0, {json.dumps(COLAB_CHECKOUT)})"
    )


def colab_url(notebook: str) -> str:
    """The address that opens ``notebook`` (a path in the repository, e.g.
    ``lessons/01_rl_and_the_bellman_equation.ipynb``) in Google Colab."""
    repository = REPOSITORY_URL.removeprefix("https://github.com/")
    return (f"https://colab.research.google.com/github/{repository}/blob/"
            f"{REPOSITORY_BRANCH}/{notebook}")


def binder_url(notebook: str | None = None) -> str:
    """The address that builds the repository on mybinder.org (from ``binder/``) and opens
    ``notebook`` in JupyterLab, or the lessons folder when None."""
    repository = REPOSITORY_URL.removeprefix("https://github.com/")
    where = f"labpath={quote(notebook, safe='')}" if notebook else "urlpath=lab/tree/lessons"
    return f"https://mybinder.org/v2/gh/{repository}/{REPOSITORY_BRANCH}?{where}"
