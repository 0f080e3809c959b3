"""Which variant of the package these tests run against: pure Python, or the compiled core.

A compiled build (``AIOFINS_MYPYC=1``, docs/packaging.md) turns the modules listed in
pyproject.toml's ``[tool.aiofins.mypyc] modules`` into C extensions. CI installs that wheel
in a venv of its own and runs the tests there with ``AIOFINS_EXPECT_COMPILED=1``: then every
listed module must be an extension module, imported from the installed wheel. Anywhere
else (the editable install of README's test command) every one must be its ``.py`` source,
so a test run always says which variant it proved.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import os
import sys
from pathlib import Path

import pytest

import aiofins

ROOT = Path(__file__).resolve().parent.parent

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[import-not-found, unused-ignore]

#: The modules a compiled build compiles: the one list, pyproject.toml's.
MODULES: list[str] = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["aiofins"][
    "mypyc"
]["modules"]

EXPECT_COMPILED = os.environ.get("AIOFINS_EXPECT_COMPILED") == "1"


def _is_extension(module_name: str) -> bool:
    origin = importlib.import_module(module_name).__file__
    assert origin is not None
    return origin.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES))


def test_the_list_names_modules_of_the_package() -> None:
    assert sorted(set(MODULES)) == MODULES, "keep the list sorted, each module once"
    for name in MODULES:
        assert name.startswith("aiofins."), name
        source = ROOT / "src" / Path(*name.split(".")).with_suffix(".py")
        assert source.is_file(), f"{name}: no {source.relative_to(ROOT)}"


@pytest.mark.skipif(not EXPECT_COMPILED, reason="runs in the compiled venv (CI)")
def test_the_compiled_variant_runs_every_listed_module_compiled() -> None:
    installed = Path(aiofins.__file__).resolve().parent
    assert ROOT / "src" not in installed.parents, f"imported from the source tree: {installed}"
    assert [name for name in MODULES if not _is_extension(name)] == []
    # One shared library holds the compiled code; each listed module is a shim into it.
    assert list(installed.glob("_core__mypyc.*")), "the shared library of the compiled core"


@pytest.mark.skipif(EXPECT_COMPILED, reason="the compiled venv runs the compiled variant")
def test_the_pure_variant_runs_every_module_from_its_source() -> None:
    assert [name for name in MODULES if _is_extension(name)] == []
    assert not list(Path(aiofins.__file__).resolve().parent.glob("_core__mypyc.*"))
