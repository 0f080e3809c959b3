"""Every ```python example in docs/ and README.md runs as a user would run it: in a
subprocess, with ``PLC_URL`` pointing at a virtual PLC of its own (an example reads where its
PLC is from ``PLC_URL``, so a user runs it against a real PLC without editing it).

A block whose first line is ``# top-level await`` is notebook code (Jupyter, IPython,
``python -m asyncio``): it is compiled with top-level ``await`` allowed and run on an asyncio
loop, as a notebook would run it. A block whose first line is ``# runs until stopped`` is a
service: it must print a first line, then stop cleanly (exit 0) on SIGTERM, as systemd and
Docker stop it. A block whose first line is ``# app.py`` is an ASGI app: uvicorn serves it.
"""

from __future__ import annotations

import importlib.util
import json
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from aiofins.simulator import Mode, VirtualPLC
from tests.simulated import RunningPLC, simulated_plc

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)
TOP_LEVEL_AWAIT = "# top-level await"
SERVICE = "# runs until stopped"
ASGI_APP = "# app.py"

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
    for path in [ROOT / "README.md", *sorted(ROOT.glob("docs/**/*.md"))]:
        for i, match in enumerate(BLOCK.finditer(path.read_text())):
            code = match.group(1)
            if "# not runnable" in code:
                continue
            name = path.name if path.parent == ROOT else path.relative_to(ROOT / "docs")
            out.append((f"{name}#{i + 1}", code))
    return out


EXAMPLES = _examples()


@pytest.mark.parametrize(("name", "code"), EXAMPLES, ids=[n for n, _ in EXAMPLES])
def test_doc_example_runs(name: str, code: str, tmp_path: Path) -> None:
    if code.startswith(ASGI_APP):
        pytest.importorskip("uvicorn", reason="the app is served by uvicorn")
        _serve(code, tmp_path, APP_CHECKS[name.split("#")[0]])
        return
    if code.startswith(TOP_LEVEL_AWAIT):
        command, stdin = [sys.executable, "-c", NOTEBOOK_RUNNER], code
    else:
        command, stdin = [sys.executable, "-c", code], None
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as sim:  # as `aiofins simulate` serves it
        if code.startswith(SERVICE):
            _run_service(command, sim.env(), tmp_path)
            return
        result = subprocess.run(  # in a folder of its own: a block may write files
            command, input=stdin, capture_output=True, text=True, cwd=tmp_path, env=sim.env()
        )
    assert result.returncode == 0, result.stderr[-2000:]


def _run_service(command: list[str], env: dict[str, str], cwd: Path) -> None:
    """Start it, read its first line of output, stop it as systemd would: exit code 0."""
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=cwd)  # fmt: skip
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate()
    finally:
        proc.kill()
        proc.wait()
    assert first, err
    assert proc.returncode == 0 and "Traceback" not in err, err


def _http(method: str, url: str, body: object = None) -> tuple[int, Any]:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(url, data, method=method)
    request.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(request) as reply:
            return reply.status, json.loads(reply.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def _check_recipe_app(base: str, sim: RunningPLC) -> None:
    """recipes.md's FastAPI app: reads, writes and the error mapping."""
    assert _http("PUT", f"{base}/plc/D100", [1, 2, 3]) == (200, {"written": 3})
    assert sim.call(sim.plc.read, "D100", 3) == [1, 2, 3]
    reply = _http("GET", f"{base}/plc/D100?count=3")
    assert reply == (200, {"address": "D100", "values": [1, 2, 3]})
    assert _http("GET", f"{base}/plc/Q100")[0] == 400  # no such area
    assert _http("PUT", f"{base}/plc/A0", [1])[0] == 409  # A0 is read-only


def _check_metrics_app(base: str, sim: RunningPLC) -> None:
    """observability.md's app: a read, then its latency among the metrics."""
    sim.call(sim.plc.write, "D100", [42])
    assert _http("GET", f"{base}/plc/D100") == (200, [42])
    with urllib.request.urlopen(f"{base}/metrics") as reply:
        text = reply.read().decode()
    assert 'aiofins_request_duration_seconds_count{endpoint="udp://127.0.0.1:' in text
    assert 'family="memory"} 1.0' in text


def _check_pool_app(base: str, sim: RunningPLC) -> None:
    """pool.md's app: a configured PLC by name; any other name is refused."""
    sim.call(sim.plc.write, "D10", [5, 6])
    assert _http("GET", f"{base}/plc/press-1/D10?count=2") == (200, {"values": [5, 6]})
    assert _http("GET", f"{base}/plc/10.0.0.1/D10") == (404, {"detail": "no PLC named '10.0.0.1'"})


#: What each page's ``# app.py`` block is asked over HTTP.
APP_CHECKS: dict[str, Callable[[str, RunningPLC], None]] = {
    "recipes.md": _check_recipe_app,
    "observability.md": _check_metrics_app,
    "pool.md": _check_pool_app,
}


def _serve(code: str, folder: Path, check: Callable[[str, RunningPLC], None]) -> None:
    """The block saved as app.py, served by ``uvicorn app:app`` as the page says, with
    ``PLC_URL`` at a virtual PLC, asked over real HTTP by ``check``."""
    (folder / "app.py").write_text(code)
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as sim:
        server = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "app:app", "--port", "0"],
            stderr=subprocess.PIPE,
            text=True,
            env=sim.env(),
            cwd=folder,
        )
        try:
            assert server.stderr is not None
            seen = []
            for line in server.stderr:  # uvicorn says where it listens once it does
                seen.append(line)
                match = re.search(r"Uvicorn running on (http://\S+)", line)
                if match:
                    base = match.group(1)
                    break
            else:
                raise AssertionError("".join(seen))
            check(base, sim)
        finally:
            server.terminate()
            server.wait()


def test_the_new_pages_have_examples() -> None:
    pages = {name.split("#")[0] for name, _ in EXAMPLES}
    assert {"getting-started.md", "recipes.md", "troubleshooting.md", "sync.md"} <= pages
    assert "README.md" in pages


@pytest.mark.parametrize(
    "page", ["README.md", "docs/index.md", "docs/getting-started.md", "docs/recipes.md"]
)
def test_the_first_pages_point_their_examples_at_plc_url(page: str) -> None:
    """What a newcomer copies first reads PLC_URL (udp://127.0.0.1, where `aiofins simulate`
    answers, without it) and starts no simulator of its own."""
    blocks = BLOCK.findall((ROOT / page).read_text())
    assert blocks
    for code in blocks:
        assert 'os.environ.get("PLC_URL", "udp://127.0.0.1")' in code, code


#: A connection to a PLC named in the code (a user would have to edit it).
LITERAL_URL = re.compile(r"""(connect|client|Pool|add_group)\([^)]*["'](udp|tcp|serial)://""")


@pytest.mark.parametrize("name", [n for n, _ in EXAMPLES])
def test_examples_are_starting_points_not_self_tests(name: str) -> None:
    """Outside the simulator's own page an example talks to the PLC at PLC_URL: it does not
    start a virtual PLC around itself, drive a test client, or hard-code an address."""
    code = dict(EXAMPLES)[name]
    if name.startswith("simulator.md"):
        return
    assert "run_simulator" not in code and "TestClient" not in code, code
    assert not LITERAL_URL.search(code), code


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
