"""The session package's shape (issue #25 item 1), read from its source with ``ast``.

- No function or method of ``src/aiofins/session/`` is longer than :data:`MAX_DEF_LINES`
  lines (decorators, signature, docstring and body): a long def is split into named steps.
- Its modules import in one direction: :class:`~aiofins.session.Session` (``core.py``)
  composes its parts (SID spaces, slots, breaker, watcher, batch ...); no part imports
  ``core.py``, not even for type checking (a part that needs the session's members says
  which in a small :class:`typing.Protocol`), and no import among the parts goes round in
  a circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import aiofins.session

PACKAGE = Path(aiofins.session.__file__).parent
#: The longest def allowed, in lines.
MAX_DEF_LINES = 60
#: Defs allowed more lines, each for a stated reason. ``Session.request`` writes out the
#: common case of ``begin()`` and of ``finish()`` (two Python calls less per request:
#: issue #22's bound on instructions per request); every other case goes through them.
LONGER = {"core.py request": 95}
#: The module that composes the others (and the package's ``__init__``, which exports it).
WHOLE = {"core", "__init__"}


def _modules() -> dict[str, ast.Module]:
    return {path.stem: ast.parse(path.read_text(), str(path)) for path in PACKAGE.glob("*.py")}


def _imports(tree: ast.Module) -> set[str]:
    """The session modules ``tree`` imports (``from .x import``, ``from . import x``), at
    run time or under ``TYPE_CHECKING`` alike."""
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module is None:
                found.update(alias.name for alias in node.names)
            else:
                found.add(node.module.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            parts = node.module.split(".")
            if parts[:2] == ["aiofins", "session"] and len(parts) > 2:
                found.add(parts[2])
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[:2] == ["aiofins", "session"] and len(parts) > 2:
                    found.add(parts[2])
    return found


def test_the_modules_are_found() -> None:
    modules = _modules()
    assert {"core", "batch", "spaces", "watcher", "sids", "slots", "breaker"} <= set(modules)


def _lengths() -> dict[str, int]:
    """Each def's length in lines, by ``"module.py name"`` (the longest of a name)."""
    lengths: dict[str, int] = {}
    for name, tree in sorted(_modules().items()):
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                assert node.end_lineno is not None
                first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                where = f"{name}.py {node.name}"
                lengths[where] = max(lengths.get(where, 0), node.end_lineno - first + 1)
    return lengths


def test_no_def_is_longer_than_60_lines() -> None:
    lengths = _lengths()
    long = {where for where, n in lengths.items() if n > LONGER.get(where, MAX_DEF_LINES)}
    assert long == set()
    # Each allowance is in use: the def is there and needs it.
    assert {where: lengths.get(where, 0) > MAX_DEF_LINES for where in LONGER} == {
        where: True for where in LONGER
    }


def test_no_part_imports_the_session() -> None:
    upward = [
        f"{name}.py imports core.py"
        for name, tree in sorted(_modules().items())
        if name not in WHOLE and "core" in _imports(tree)
    ]
    assert upward == []


def test_the_parts_import_in_one_direction() -> None:
    graph = {
        name: _imports(tree) - {name} for name, tree in _modules().items() if name != "__init__"
    }
    circles: list[list[str]] = []

    def visit(name: str, path: list[str]) -> None:
        for imported in sorted(graph.get(name, ())):
            if imported in path:
                circle = path[path.index(imported) :]
                if min(circle) == imported:  # each circle once, from its first module
                    circles.append([*circle, imported])
            elif imported not in done:
                visit(imported, [*path, imported])
        done.add(name)

    done: set[str] = set()
    for name in sorted(graph):
        if name not in done:
            visit(name, [name])
    assert circles == []
