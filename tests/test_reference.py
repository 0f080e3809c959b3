"""The API reference documents every public name: each name in ``__all__`` of ``aiofins``
and of its public subpackages has an entry (``::: module.Name``) on a page of docs/api/,
and each of those modules has its own description rendered there."""

from __future__ import annotations

import importlib
import inspect
import re
import typing
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
API = ROOT / "docs" / "api"
DIRECTIVE = re.compile(r"^::: ([\w.]+)$", re.MULTILINE)

#: The modules whose ``__all__`` is public surface.
PUBLIC = (
    "aiofins",
    "aiofins.sync",
    "aiofins.simulator",
    "aiofins.bulk",
    "aiofins.tags",
    "aiofins.gateway",
    "aiofins.hooks",
    "aiofins.metrics",
    "aiofins.tracing",
)
#: Modules whose description a page renders (``::: aiofins.pool`` with ``members: false``):
#: a class's docstring may point to it ("see aiofins.pool").
DESCRIBED = (
    "aiofins.endpoint",
    "aiofins.pool",
    "aiofins.tags",
    "aiofins.simulator",
    "aiofins.bulk",
    "aiofins.gateway",
    "aiofins.hooks",
)


def _directives() -> list[str]:
    return [
        path for page in sorted(API.glob("*.md")) for path in DIRECTIVE.findall(page.read_text())
    ]


def _resolve(path: str) -> object:
    """The object a ``::: path`` directive renders (a module, or a name in one)."""
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            target: object = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            target = getattr(target, name)
        return target
    raise AssertionError(f"{path}: no such module")


def test_every_directive_names_something_that_exists() -> None:
    for path in _directives():
        _resolve(path)  # raises for a name that is gone


def _missing(module: str, directives: list[str]) -> list[str]:
    """The names of ``module.__all__`` that none of ``directives`` renders."""
    documented = {id(_resolve(path)) for path in directives}
    mod = importlib.import_module(module)
    exported = getattr(mod, "__all__", None)
    assert exported, f"{module} has no __all__"
    return [
        name
        for name in exported
        if name != "__version__" and id(getattr(mod, name)) not in documented
    ]


@pytest.mark.parametrize("module", PUBLIC)
def test_every_public_name_has_a_reference_entry(module: str) -> None:
    """A name exported by ``__all__`` without an entry is a name users import and cannot
    look up: this fails until a page of docs/api/ has ``::: module.Name`` for it (the
    module it is defined in works too)."""
    missing = _missing(module, _directives())
    assert not missing, f"no docs/api entry for {module}: {', '.join(missing)}"


@pytest.mark.parametrize("module", DESCRIBED)
def test_module_descriptions_are_rendered(module: str) -> None:
    assert module in _directives(), f"no '::: {module}' in docs/api"
    assert importlib.import_module(module).__doc__


def test_the_check_sees_a_missing_entry() -> None:
    without_pool = [path for path in _directives() if path != "aiofins.Pool"]
    assert _missing("aiofins", without_pool) == ["Pool"]
    assert _missing("aiofins", [*without_pool, "aiofins.pool.Pool"]) == []


def _classes(hint: object) -> list[type]:
    """The aiofins classes a type hint names (``list[FileEntry] | None``: FileEntry)."""
    args = typing.get_args(hint)
    if args:
        return [cls for arg in args for cls in _classes(arg)]
    if inspect.isclass(hint) and hint.__module__.startswith("aiofins"):
        return [hint]
    return []


def test_every_type_a_client_call_returns_has_an_entry() -> None:
    """What ``await plc.cpu_unit_status_read()`` returns is a type users read attributes of:
    it has a page entry (CpuUnitStatus, ClockData, ... each result of the manual's commands)."""
    import aiofins

    documented = {id(_resolve(path)) for path in _directives()}
    missing = set()
    for name, method in inspect.getmembers(aiofins.Client, callable):
        if name.startswith("_"):
            continue
        returned = typing.get_type_hints(method).get("return")
        missing |= {
            f"{cls.__module__}.{cls.__qualname__} ({name})"
            for cls in _classes(returned)
            if id(cls) not in documented
        }
    assert not missing, sorted(missing)
