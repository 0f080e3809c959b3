"""Every ```python example in docs/ runs (against the embedded simulator).

A block whose first line is ``# top-level await`` is notebook code (Jupyter, IPython,
``python -m asyncio``): it is compiled with top-level ``await`` allowed and run on an asyncio
loop, as a notebook would run it.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)
TOP_LEVEL_AWAIT = "# top-level await"

#: Runs a notebook cell's code (stdin) the way IPython's autoawait does.
NOTEBOOK_RUNNER = """
import ast, asyncio, sys
code = compile(sys.stdin.read(), "<cell>", "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)
result = eval(code, {"__name__": "__main__"})
if asyncio.iscoroutine(result):
    asyncio.run(result)
"""


def _examples() -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for path in sorted(ROOT.glob("docs/**/*.md")):
        for i, match in enumerate(BLOCK.finditer(path.read_text())):
            code = match.group(1)
            if "# not runnable" in code:
                continue
            out.append((f"{path.relative_to(ROOT / 'docs')}#{i + 1}", code))
    return out


EXAMPLES = _examples()


@pytest.mark.parametrize("code", [c for _, c in EXAMPLES], ids=[n for n, _ in EXAMPLES])
def test_doc_example_runs(code: str) -> None:
    if code.startswith(TOP_LEVEL_AWAIT):
        command, stdin = [sys.executable, "-c", NOTEBOOK_RUNNER], code
    else:
        command, stdin = [sys.executable, "-c", code], None
    result = subprocess.run(
        command, input=stdin, capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode == 0, result.stderr[-2000:]


def test_the_new_pages_have_examples() -> None:
    pages = {name.split("#")[0] for name, _ in EXAMPLES}
    assert {"getting-started.md", "recipes.md", "troubleshooting.md", "sync.md"} <= pages


def test_a_notebook_block_runs_its_awaits() -> None:
    """The runner for notebook blocks really awaits (a failing await fails the block)."""
    code = f"{TOP_LEVEL_AWAIT}\nimport anyio\nawait anyio.sleep(0)\nraise SystemExit(3)\n"
    result = subprocess.run(
        [sys.executable, "-c", NOTEBOOK_RUNNER], input=code, capture_output=True, text=True
    )
    assert result.returncode == 3, result.stderr


def _hook(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, ROOT / "docs" / "_hooks" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_has_the_help_of_every_subcommand() -> None:
    from aiofins.cli import build_parser

    hook = _hook("cli_reference")
    page = (ROOT / "docs" / "cli-reference.md").read_text()
    rendered = hook.on_page_markdown(page, page=None)
    assert hook.MARKER not in rendered
    subparsers = build_parser()._subparsers
    assert subparsers is not None
    (action,) = subparsers._group_actions
    assert isinstance(action.choices, dict) and len(action.choices) >= 12
    for name, parser in action.choices.items():
        assert f"## `aiofins {name}`" in rendered
        assert f"usage: aiofins {name}" in rendered
        assert parser.format_usage().split()[2] == name


def test_sphinx_roles_become_code_spans() -> None:
    hook = _hook("api_reference")
    text = "See :class:`~aiofins.Client` and :meth:`Session.request_many`, :data:`X`."
    assert hook.ROLE.sub(hook._code, text) == "See `Client` and `Session.request_many`, `X`."


def test_the_api_reference_covers_every_export() -> None:
    """A name no page of docs/api/ groups gets its entry on the 'Other exports' page."""
    import aiofins

    hook = _hook("other_exports")
    api = ROOT / "docs" / "api"
    exported = list(aiofins.__all__)
    rendered = hook.render(api, exported)
    for name in hook.uncovered(api, exported):
        assert f"::: aiofins.{name}" in rendered
    assert "::: aiofins.Client" not in rendered  # it has its page
    later = [*exported, "SomethingNew"]
    assert hook.uncovered(api, later) == [*hook.uncovered(api, exported), "SomethingNew"]
    assert hook.render(api, later).endswith("::: aiofins.SomethingNew")
    page = (api / "other.md").read_text()
    assert hook.MARKER in page


def test_an_async_context_manager_is_shown_as_one() -> None:
    import griffe

    hook = _hook("api_reference")
    package = griffe.load(
        "aiofins",
        search_paths=[str(ROOT / "src")],
        extensions=griffe.load_extensions(hook.ApiReference),
    )
    run_simulator = package["simulator.run_simulator"]
    assert "async" not in run_simulator.labels
    assert str(run_simulator.returns) == "AbstractAsyncContextManager[Simulator]"
