"""MkDocs hook: an API reference entry for every name ``aiofins`` exports.

The pages in ``docs/api/`` document the exports by hand, grouped (``::: aiofins.Client``).
``docs/api/other.md`` holds a marker line that each build replaces with an entry for every
name of ``aiofins.__all__`` that no page names, so a new export is in the reference from the
day it is added (and shows up there, waiting for a page of its own).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

MARKER = "<!-- aiofins-other-exports -->"
DIRECTIVE = re.compile(r"^::: aiofins\.(\w+)$", re.MULTILINE)


def uncovered(api_dir: Path, exported: list[str]) -> list[str]:
    """The exported names that no page of ``api_dir`` has an entry for."""
    covered = {
        name for page in api_dir.glob("*.md") for name in DIRECTIVE.findall(page.read_text())
    }
    return [name for name in exported if name != "__version__" and name not in covered]


def render(api_dir: Path, exported: list[str]) -> str:
    names = uncovered(api_dir, exported)
    if not names:
        return "None: every name is on one of the pages before this one."
    return "\n\n".join(f"::: aiofins.{name}" for name in names)


def on_page_markdown(markdown: str, *, page: Any, config: Any, **kwargs: Any) -> str:
    if MARKER not in markdown:
        return markdown
    import aiofins

    api_dir = Path(config["docs_dir"]) / "api"
    return markdown.replace(MARKER, render(api_dir, list(aiofins.__all__)))
