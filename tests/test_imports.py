"""No import circle among the ``dlo_course`` modules, read from the source (nothing imported).

Two graphs are checked, both must be acyclic:

* **module level**: every ``import`` that runs when a module is imported (in the module body,
  including under ``if``/``try``/``with`` and in class bodies; not under
  ``if TYPE_CHECKING:``, which never runs);
* **with function-local imports**: the same, plus the imports inside functions and methods.
  They count too: the library imports PyBullet, torch or a heavy sibling inside a function
  only to load it late (``# imports PyBullet: only when needed``), never to get round a
  circle, and a circle hidden in a function is still two modules that each need the other
  (the one this test was written for: env -> robustness -> evaluation -> env).

Importing ``dlo_course.a.b`` is an edge to ``dlo_course.a.b`` only (not to the packages
above it, which Python initialises first anyway); ``from dlo_course import x`` is an edge to
the module ``dlo_course.x`` when there is one, else to the package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "dlo_course"
PACKAGE = PACKAGE_DIR.name


def module_files() -> dict[str, Path]:
    """``{dotted module name: source file}`` for every module of the package."""
    modules = {}
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        parts = (PACKAGE, *path.relative_to(PACKAGE_DIR).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _targets(node: ast.Import | ast.ImportFrom, module: str, is_package: bool,
             modules: dict[str, Path]) -> set[str]:
    """The package modules an import statement imports."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        base = node.module or ""
        if node.level:  # relative: resolve against the importing module's package
            package = module.split(".") if is_package else module.split(".")[:-1]
            package = package[:len(package) - (node.level - 1)]
            base = ".".join(package + ([base] if base else []))
        names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                 for alias in node.names]
    found = set()
    for name in names:
        # "import dlo_course.a.b" names a module; keep the longest prefix that is one
        while name and name not in modules:
            name = name.rpartition(".")[0]
        if name:
            found.add(name)
    return found


def imports(module: str, path: Path, modules: dict[str, Path]
            ) -> tuple[set[str], set[str]]:
    """(module-level imports, function-local imports) of one module, package modules only."""
    top: set[str] = set()
    local: set[str] = set()
    is_package = path.name == "__init__.py"

    def visit(node: ast.AST, in_function: bool) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child, in_function)
            return
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            (local if in_function else top).update(_targets(node, module, is_package, modules))
            return
        inside = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                  ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, inside)

    visit(ast.parse(path.read_text(encoding="utf-8"), str(path)), False)
    top.discard(module)
    local.discard(module)
    return top, local - top


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of nodes (first == last), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def import_graphs() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    modules = module_files()
    top, every = {}, {}
    for module, path in modules.items():
        module_level, function_local = imports(module, path, modules)
        top[module] = module_level
        every[module] = module_level | function_local
    return top, every


def test_the_parser_sees_the_package():
    top, every = import_graphs()
    assert {"dlo_course", "dlo_course.env", "dlo_course.simulation"} <= set(top)
    assert "dlo_course.simulation" in top["dlo_course.env"]
    assert "dlo_course.env" in every["dlo_course.trainer"]  # a function-local import
    assert "dlo_course.env" not in top["dlo_course.trainer"]


def test_find_cycle_finds_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


@pytest.mark.parametrize("which", ["module level", "with function-local imports"])
def test_no_import_cycle(which):
    top, every = import_graphs()
    cycle = find_cycle(top if which == "module level" else every)
    assert cycle is None, "import circle: " + " -> ".join(cycle)
