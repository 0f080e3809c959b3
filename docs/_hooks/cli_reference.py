"""MkDocs hook: the CLI reference rendered from the argparse parser at build time.

``docs/cli-reference.md`` holds a marker line; each build replaces it with the ``--help`` of
``aiofins`` and of every subcommand, as ``build_parser()`` makes them, so the reference cannot
drift from the code and no generated file is checked in.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

MARKER = "<!-- aiofins-cli-reference -->"


def _help(parser: argparse.ArgumentParser) -> str:
    # A fixed width and no colours (Python 3.14 colours help on a terminal).
    saved = {name: os.environ.get(name) for name in ("COLUMNS", "NO_COLOR", "PYTHON_COLORS")}
    os.environ.update(COLUMNS="100", NO_COLOR="1", PYTHON_COLORS="0")
    try:
        return parser.format_help()
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def render() -> str:
    """Markdown for the top-level parser and each subcommand, in ``--help`` order."""
    from aiofins.cli import build_parser

    parser = build_parser()
    sections = ["## `aiofins`", "", "```text", _help(parser).rstrip(), "```", ""]
    for action in parser._subparsers._group_actions if parser._subparsers else ():
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                sections += [f"## `aiofins {name}`", "", "```text", _help(sub).rstrip(), "```", ""]
    return "\n".join(sections)


def on_page_markdown(markdown: str, *, page: Any, **kwargs: Any) -> str:
    if MARKER in markdown:
        return markdown.replace(MARKER, render())
    return markdown
