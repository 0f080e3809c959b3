"""The gallery's async code under every backend: each example's coroutine, imported and
awaited under asyncio, uvloop and trio against a virtual PLC on the same event loop (the
subprocess tests run them as a user does, on asyncio; trio_counter.py on trio)."""

from __future__ import annotations

import importlib.util
from collections.abc import Awaitable, Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from aiofins.simulator import Mode, VirtualPLC, run_simulator
from tests.simulated import ROOT

pytestmark = pytest.mark.anyio


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"gallery_{name}", ROOT / "examples" / name)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


Call = Callable[[Any, str, Path], Awaitable[object]]

#: example -> how to await its coroutine (module, PLC URL, a scratch folder), what it prints
CASES: dict[str, tuple[Call, str]] = {
    "recipe.py": (lambda m, url, tmp: m.main(3, None), "recipe 3 at D1060:"),
    "log_to_csv.py": (
        lambda m, url, tmp: m.log({"t": "D100:float32"}, 0.02, 2, None),
        "time,t",
    ),
    "backup_program.py": (lambda m, url, tmp: m.backup(tmp), "4 parameter areas"),
    "sync_clock.py": (lambda m, url, tmp: m.sync(3600.0, True), "within the tolerance"),
    "copy_memory.py": (
        lambda m, url, tmp: m.copy(url, url, "D0", 10, "D100"),
        "wrote and verified 10 words",
    ),
    "cpu_status.py": (lambda m, url, tmp: m.check(), "mode         RUN"),
    "error_log.py": (lambda m, url, tmp: m.show(False), "0 of 20 error log records"),
    "line_overview.py": (lambda m, url, tmp: m.overview([url]), "state=0"),
    "trio_counter.py": (lambda m, url, tmp: m.count("CIO 0.00", 0.05, 0.01), "0 parts in"),
    "polling_daemon.py": (lambda m, url, tmp: m.poll([url], 0.02, 0.1), '"plc": "plc0"'),
}


@pytest.mark.parametrize("name", sorted(CASES))
async def test_example_runs_under_this_backend(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    module = _load(name)
    call, printed = CASES[name]
    async with run_simulator(VirtualPLC(mode=Mode.RUN), udp=("127.0.0.1", 0)) as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        module.__dict__["PLC_URL"] = url  # what PLC_URL=... in the environment does
        await call(module, url, tmp_path)
    assert printed in capsys.readouterr().out
