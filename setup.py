"""setuptools' build script: the pure-Python package, or with ``AIOFINS_MYPYC=1`` a compiled core.

Everything about the package is declared in pyproject.toml; this script only adds, when the
environment variable ``AIOFINS_MYPYC`` is ``1``, the C extensions mypyc makes of the modules
listed in pyproject.toml's ``[tool.aiofins.mypyc] modules`` (docs/packaging.md). Without the
variable (``pip install aiofins``, ``pip install -e .``, the pure wheel) it adds nothing.

In an isolated build (``python -m build``, ``pip wheel``) setuptools asks this script what
the build needs before building: while mypyc cannot be imported, a compiled build answers
with mypy (which brings mypyc) and the packages mypy needs to type-check the sources;
the frontend installs them and runs the script again, and then it compiles.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path
from typing import Any

from setuptools import setup

ROOT = Path(__file__).resolve().parent

#: What a compiled build needs besides setuptools: mypyc (in mypy) and what the compiled
#: modules import, for mypy's type checks (tomli reads pyproject.toml before Python 3.11).
COMPILE_REQUIRES = ["mypy>=1.16", "anyio>=4.4", "trio>=0.25", "tomli>=1.1; python_version < '3.11'"]


def compiled_modules() -> list[str]:
    """The dotted names of the modules a compiled build compiles (pyproject.toml's list)."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    with open(ROOT / "pyproject.toml", "rb") as file:
        config = tomllib.load(file)
    modules: list[str] = config["tool"]["aiofins"]["mypyc"]["modules"]
    return modules


def compile_options() -> dict[str, Any]:
    """``setup()`` arguments of a compiled build; none for the pure package."""
    wanted = os.environ.get("AIOFINS_MYPYC", "")
    if wanted in ("", "0"):
        return {}
    if wanted != "1":
        raise SystemExit(f"AIOFINS_MYPYC={wanted!r}: set it to 1 (compile) or 0/unset (pure)")
    commands = set(sys.argv[1:])
    if commands & {"editable_wheel", "develop"}:
        raise SystemExit("AIOFINS_MYPYC=1 builds a wheel; an editable install is pure Python")
    try:
        from mypyc.build import mypycify
    except ImportError:  # setuptools asking what the build needs: tell it
        return {"setup_requires": COMPILE_REQUIRES}
    if not commands & {"bdist_wheel", "build", "build_ext"}:
        return {}  # metadata only (egg_info, dist_info, sdist): nothing to compile
    # A build directory of its own, emptied of the last build's extensions (a module taken
    # off the list must not ship its old one); mypyc's C files and the objects stay, so an
    # unchanged module is not compiled again.
    base = Path("build", "mypyc")
    shutil.rmtree(base / "lib", ignore_errors=True)
    paths = [str(Path("src", *name.split(".")).with_suffix(".py")) for name in compiled_modules()]
    extensions = mypycify(
        paths,
        opt_level="3",
        debug_level="0",
        group_name="aiofins._core",  # one shared library, aiofins/_core__mypyc.*.so
        target_dir=str(base / "c"),
    )
    return {
        "ext_modules": extensions,
        "options": {"build": {"build_base": str(base), "build_lib": str(base / "lib")}},
    }


setup(**compile_options())
