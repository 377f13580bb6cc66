"""Delegation checks: an exercise cell must be the student's own work.

The ``dlo_course`` library holds the reference answers, so an exercise cell that uses it
(other than its notebook helpers, :data:`LIBRARY_HELPERS`) is rejected before it runs, with
the reason (:func:`delegation_problems`, read from the source); the sandbox also makes the
reference raise if the answer reaches it anyway (:mod:`dlo_course.grading.sandbox`). The
grading package itself is not a helper: it reads the grader's own answers
(:func:`dlo_course.grading.bundle.answer_result`).
"""

from __future__ import annotations

from typing import Iterable

LIBRARY = "dlo_course"
LIBRARY_HELPERS = ("dlo_course.notebook",)  # fast_mode, output_dir, ...: no answers
_DYNAMIC = {"__import__": "__import__", "importlib": "importlib", "eval": "eval",
            "exec": "exec", "compile": "compile", "globals": "globals()"}


def _library_names(sources: Iterable[str]) -> dict[str, str]:
    """Names that the cells bind to the library: name -> dotted path (``ddpg`` ->
    ``dlo_course.ddpg``, ``ReplayBuffer`` -> ``dlo_course.replay_buffer.ReplayBuffer``)."""
    import ast

    bound: dict[str, str] = {}
    for source in sources:
        try:
            tree = ast.parse(_strip_magics(source))
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == LIBRARY or alias.name.startswith(LIBRARY + "."):
                        if alias.asname:
                            bound[alias.asname] = alias.name
                        else:
                            bound[alias.name.split(".")[0]] = LIBRARY
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and (
                    node.module == LIBRARY or node.module.startswith(LIBRARY + ".")):
                for alias in node.names:
                    bound[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return bound


def _strip_magics(source: str) -> str:
    return "\n".join("" if line.lstrip().startswith(("%", "!")) else line
                     for line in source.split("\n"))


def delegation_problems(source: str, context: Iterable[str] = (),
                        references: Iterable[str] = ()) -> list[str]:
    """Why an exercise cell's ``source`` is not the student's own work, if it is not: it uses
    the ``dlo_course`` library (which holds the reference answers) other than its
    notebook helpers (:data:`LIBRARY_HELPERS`), whether by a name that ``context`` (the setup and other
    exercise cells) or the cell imports, by subclassing, or through ``getattr``,
    ``importlib``, ``__import__``, ``sys.modules``, ``eval``/``exec`` or a string naming the
    library; or it names a class of ``references`` outside the library (``torch.optim.Adam``
    for an Adam step written by hand). An empty list: nothing wrong."""
    import ast

    try:
        tree = ast.parse(_strip_magics(source))
    except SyntaxError:
        return []  # the sandbox reports the syntax error itself
    bound = _library_names([*context, source])
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    problems: list[str] = []

    def add(text: str) -> None:
        if text not in problems:
            problems.append(text)

    def allowed(dotted: str) -> bool:
        return any(dotted == h or dotted.startswith(h + ".") for h in LIBRARY_HELPERS)

    outside = {}  # a class name of a reference outside the library -> its dotted path
    for dotted in references:
        if not dotted.startswith(LIBRARY + "."):
            parts = dotted.split(".")
            names = [p for p in parts if p[:1].isupper()] or parts[-1:]
            outside[names[0]] = ".".join(parts[:parts.index(names[0]) + 1])
    for node in ast.walk(tree):
        name = node.id if isinstance(node, ast.Name) else \
            node.attr if isinstance(node, ast.Attribute) else None
        if name in outside:
            add(f"uses {outside[name]}")
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                if top == LIBRARY and not allowed(alias.name):
                    add(f"imports {alias.name}")
                elif top == "importlib":
                    add("imports importlib")
        elif isinstance(node, ast.ImportFrom) and node.module:
            top = node.module.split(".")[0]
            if top == LIBRARY and not allowed(node.module):
                add(f"imports from {node.module}")
            elif top == "importlib":
                add("imports from importlib")
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
            if node.id in bound:
                dotted, current = bound[node.id], node
                while isinstance(parents.get(current), ast.Attribute) \
                        and parents[current].value is current:
                    current = parents[current]
                    dotted += "." + current.attr
                if not allowed(dotted):
                    add(f"uses {dotted}")
            elif node.id in _DYNAMIC:
                add(f"uses {_DYNAMIC[node.id]}")
            elif node.id == "getattr":
                call = parents.get(node)
                if isinstance(call, ast.Call) and call.args and any(
                        isinstance(n, ast.Name) and n.id in bound for n in ast.walk(call.args[0])):
                    add("uses getattr on the library")
        elif isinstance(node, ast.Attribute) and node.attr == "modules" \
                and isinstance(node.value, ast.Name) and node.value.id == "sys":
            add("uses sys.modules")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and LIBRARY in node.value:
            add(f"names the library in a string ({node.value!r})")
    return problems


def delegation_message(name: str, problems: list[str]) -> str:
    return (f"{name}: rejected, the answer is not written in the exercise cell: it "
            f"{'; '.join(problems)}. The dlo_course library holds the reference answers, so "
            f"an exercise cell may not call, subclass or fetch anything of it (its helpers "
            f"in dlo_course.notebook excepted): write the code yourself.")
