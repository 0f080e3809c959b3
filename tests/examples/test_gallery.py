"""The examples gallery: every script is listed in docs/examples.md, says what it shows, has
a ``--help``, and runs as a user runs it (``python examples/NAME.py``, ``PLC_URL`` pointing at
a virtual PLC), with what it prints and what it does to the PLC checked."""

from __future__ import annotations

import csv
import io
import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from datetime import datetime, timedelta
from pathlib import Path

import pytest

from aiofins.simulator import Mode, VirtualPLC
from tests.simulated import ROOT, RunningPLC, run_python, simulated_plc

EXAMPLES = ROOT / "examples"
SCRIPTS = sorted(p.name for p in EXAMPLES.glob("*.py") if p.name != "__init__.py")
GALLERY = ROOT / "docs" / "examples.md"


@pytest.fixture
def sim() -> Iterator[RunningPLC]:
    """A virtual PLC in RUN mode, as a PLC at work is."""
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as running:
        yield running


def test_there_are_at_least_twelve_examples_and_a_notebook() -> None:
    assert len(SCRIPTS) >= 12, SCRIPTS
    assert (EXAMPLES / "trend.ipynb").exists()


@pytest.mark.parametrize("name", [*SCRIPTS, "trend.ipynb"])
def test_every_example_is_in_the_gallery(name: str) -> None:
    page = GALLERY.read_text()
    assert f"[`{name}`](https://" in page or f"`examples/{name}`" in page, name
    assert re.search(rf"^## .*`{re.escape(name)}`", page, re.MULTILINE), f"no section for {name}"


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_script_says_what_it_shows_and_where_its_plc_is(name: str) -> None:
    text = (EXAMPLES / name).read_text()
    assert text.startswith('"""'), f"{name} has no docstring"
    if name != "fastapi_app.py":  # reads it in its lifespan, with the same default
        assert 'PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")' in text, name
    assert "192.168." not in text.split('"""', 2)[2], f"{name}: a plant address outside the doc"


@pytest.mark.parametrize("name", [s for s in SCRIPTS if s != "fastapi_app.py"])
def test_every_script_prints_its_help(name: str) -> None:
    result = run_python([f"examples/{name}", "--help"], {**os.environ, "PLC_URL": "udp://x"})
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: ") and not result.stderr, result.stderr
    first_line = (EXAMPLES / name).read_text().split("\n")[0].strip('"')
    assert " ".join(first_line.split()[:3]) in " ".join(result.stdout.split())


def _run(sim: RunningPLC, *args: str) -> str:
    """``python examples/ARGS...`` with ``PLC_URL`` set to ``sim``; its stdout."""
    result = run_python([str(EXAMPLES / args[0]), *args[1:]], sim.env())
    assert result.returncode == 0, f"stdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    return result.stdout


def test_recipe_loads_and_reads_setpoints(sim: RunningPLC, tmp_path: Path) -> None:
    sim.call(sim.plc.write_value, "D1068", 182.5, "float32")  # recipe 3's temperature
    sim.call(sim.plc.write_value, "D1060", "RYE", "string:16")
    out = _run(sim, "recipe.py", "3")
    assert out.splitlines() == [
        "recipe 3 at D1060:",
        "  name         'RYE'",
        "  temperature  182.5",
        "  mix_time     0",
        "  speed        0",
        "  pressure     0",
    ]
    recipe = tmp_path / "r.json"
    recipe.write_text(json.dumps({"name": "BROWN BREAD", "speed": -30, "pressure": 250_000}))
    out = _run(sim, "recipe.py", "7", "--load", str(recipe))
    assert "  speed        -30" in out.splitlines()
    assert sim.call(sim.plc.read_value, "D1140", "string:16") == "BROWN BREAD"
    assert sim.call(sim.plc.read_value, "D1151", "int16") == -30
    assert sim.call(sim.plc.read_value, "D1152", "int32") == 250_000


def test_log_to_csv_writes_one_row_per_scan(sim: RunningPLC, tmp_path: Path) -> None:
    sim.call(sim.plc.write_value, "D100", 21.5, "float32")
    sim.call(sim.plc.write_value, "D102", -7, "int32")
    sim.call(sim.plc.write, "CIO 0.00", [1])
    output = tmp_path / "log.csv"
    for _ in range(2):  # the second run appends, without a second header
        _run(sim, "log_to_csv.py", "--samples", "3", "--interval", "0.05", "--output", str(output))
    rows = list(csv.reader(io.StringIO(output.read_text())))
    assert rows[0] == ["time", "temperature", "pressure", "running"]
    assert len(rows) == 7 and all(row[1:] == ["21.5", "-7", "True"] for row in rows[1:]), rows
    datetime.fromisoformat(rows[1][0])
    out = _run(sim, "log_to_csv.py", "--samples", "1", "--interval", "0.05", "D102", "t=D100")
    assert out.splitlines()[0] == "time,D102,t" and out.splitlines()[1].endswith(",65529,0")


def test_a_script_started_by_a_test_ends_on_sigint_as_in_a_terminal() -> None:
    """Ctrl-C in a terminal sends SIGINT to a program in the foreground, whose SIGINT has its
    default action: Python raises KeyboardInterrupt. The programs these tests stop with SIGINT
    get the same, even when the suite itself runs as a background job of a script (``cmd &``
    in a non-interactive shell, as CI scripts do), whose SIGINT is ignored and would be
    inherited ignored: tests/conftest.py restores its default for the session."""
    code = "import signal; print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)"
    result = run_python(["-c", code], dict(os.environ))
    assert result.stdout == "True\n", result.stderr


def test_watch_alarms_prints_alarms_as_they_are_raised_and_cleared(sim: RunningPLC) -> None:
    sim.call(sim.plc.write, "W0.03", [1])  # active before it starts
    proc = subprocess.Popen(
        [sys.executable, str(EXAMPLES / "watch_alarms.py"), "--interval", "0.05"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=sim.env(),
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline() == f"watching 5 alarms on {sim.url}\n"
        assert proc.stdout.readline().endswith("  RAISED   emergency stop pressed (W0.03)\n")
        sim.call(sim.plc.write, "W0.01", [1])
        assert proc.stdout.readline().endswith("  RAISED   low hydraulic pressure (W0.01)\n")
        sim.call(sim.plc.write, "W0.03", [0])
        assert proc.stdout.readline().endswith("  cleared  emergency stop pressed (W0.03)\n")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err, err


def test_backup_program_saves_program_and_parameters(sim: RunningPLC, tmp_path: Path) -> None:
    program = bytes(range(256)) * 4

    def load() -> None:
        sim.plc.program[: len(program)] = program
        sim.plc.program_length = len(program)

    sim.call(load)
    out = _run(sim, "backup_program.py", "--folder", str(tmp_path))
    (folder,) = tmp_path.iterdir()
    assert folder.name.startswith("node1-")
    saved = (folder / "program.bin").read_bytes()  # up to the block with the last byte
    assert saved.startswith(program) and not any(saved[len(program) :])
    parameters = json.loads((folder / "parameters.json").read_text())
    assert len(parameters) == 4 and all(re.fullmatch("[0-9A-F]{4}", area) for area in parameters)
    assert (folder / "cpu.txt").read_text() == "CJ2M-CPU33 02.01\n"
    assert out.splitlines() == [
        f"CJ2M-CPU33: {len(saved)} program bytes, 4 parameter areas",
        f"saved in {folder}",
    ]


def test_sync_clock_sets_a_clock_that_is_an_hour_off(sim: RunningPLC) -> None:
    sim.call(sim.plc.set_clock, datetime.now() - timedelta(hours=1), None)
    out = _run(sim, "sync_clock.py", "--dry-run")
    assert re.search(r"drift -36\d\d s", out) and "would set it (--dry-run)" in out
    assert abs((sim.call(sim.plc.now) - datetime.now()).total_seconds() + 3600) < 600
    out = _run(sim, "sync_clock.py")
    assert re.search(r"drift -36\d\d s", out) and "set to " in out
    assert abs((sim.call(sim.plc.now) - datetime.now()).total_seconds()) < 600
    assert sim.call(sim.plc.weekday) == (datetime.now().weekday() + 1) % 7


def test_copy_memory_copies_between_two_plcs(sim: RunningPLC) -> None:
    words = [(7 * i) & 0xFFFF for i in range(1500)]  # more than one frame
    sim.call(sim.plc.write, "D1000", words)
    with simulated_plc() as target:
        out = _run(sim, "copy_memory.py", "D1000", "1500", "--target", target.url)
        assert target.call(target.plc.read, "D1000", 1500) == words
        assert out.splitlines()[-1] == f"wrote and verified 1500 words at D1000 on {target.url}"
    _run(sim, "copy_memory.py", "D1000", "10", "--to", "D5000")  # within one PLC
    assert sim.call(sim.plc.read, "D5000", 10) == words[:10]


def test_cpu_status_reports_mode_and_errors_with_an_exit_code(sim: RunningPLC) -> None:
    assert _run(sim, "cpu_status.py").splitlines()[:2] == [
        "model        CJ2M-CPU33 (version 02.01)",
        "mode         RUN",
    ]
    sim.call(lambda: sim.plc.raise_error(0x4101, message="OVEN 1 OVERHEAT"))
    result = run_python([str(EXAMPLES / "cpu_status.py")], sim.env())
    assert result.returncode == 2, result.stderr  # FAL: a non-fatal error
    assert "error        4101 OVEN 1 OVERHEAT" in result.stdout
    assert "  flag       FAL_ERROR" in result.stdout


def test_cpu_status_names_a_plc_that_does_not_answer() -> None:
    with simulated_plc() as sim:
        sim.go_silent()
        env = sim.env(PLC_URL=f"{sim.url}?timeout=0.2")
        result = run_python([str(EXAMPLES / "cpu_status.py")], env)
    assert result.returncode == 1
    last = result.stderr.splitlines()[-1]
    assert last.startswith("FinsTimeout: no response") and "Traceback" not in result.stderr


def test_error_log_prints_and_clears_the_log(sim: RunningPLC) -> None:
    sim.call(sim.plc.log_error, 0x80C0, 0x0001)
    sim.call(sim.plc.log_error, 0x0006)
    lines = _run(sim, "error_log.py", "--clear").splitlines()
    assert lines[0] == "2 of 20 error log records"
    assert lines[1].endswith("error 0006 0000") and lines[2].endswith("error 80C0 0001")
    assert lines[-1] == "error log cleared"
    assert sim.call(lambda: len(sim.plc.error_log)) == 0


def test_shift_report_appends_a_csv_line(sim: RunningPLC, tmp_path: Path) -> None:
    sim.call(sim.plc.write_value, "D300", 980, "uint32")
    sim.call(sim.plc.write_value, "D302", 20, "uint32")
    sim.call(sim.plc.write_value, "D304", 12, "uint16")
    sim.call(sim.plc.write_value, "D310", "P-4711", "string:12")
    shifts = tmp_path / "shifts.csv"
    _run(sim, "shift_report.py", "-o", str(shifts))
    _run(sim, "shift_report.py", "--output", str(shifts))
    rows = list(csv.reader(io.StringIO(shifts.read_text())))
    assert len(rows) == 2 and rows[0][1:] == ["P-4711", "980", "20", "12", "2.00%"]
    assert _run(sim, "shift_report.py").strip().endswith(",P-4711,980,20,12,2.00%")


def test_line_overview_has_a_row_per_plc_even_a_silent_one(sim: RunningPLC) -> None:
    sim.call(sim.plc.write_value, "D10", 1.5, "float32")
    with simulated_plc() as other:
        other.go_silent()
        silent = f"{other.url}?timeout=0.2"
        lines = _run(sim, "line_overview.py", sim.url, silent).splitlines()
    assert lines[0].split() == [sim.url, "state=0", "speed=1.5", "count=0", "fault=False"]
    assert lines[1].startswith(silent) and "FinsTimeout: no response" in lines[1]
    assert _run(sim, "line_overview.py").startswith(sim.url)  # PLC_URL alone


def test_trio_counter_counts_rising_edges(sim: RunningPLC) -> None:
    pytest.importorskip("trio")
    proc = subprocess.Popen(
        [sys.executable, str(EXAMPLES / "trio_counter.py"), "--seconds", "600"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=sim.env(),
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline() == "counting parts on CIO 0.00 for 600 s\n"
        for part in (1, 2):  # each edge once the script has seen the one before
            sim.call(sim.plc.write, "CIO 0.00", [1])
            assert proc.stdout.readline() == f"part {part} in\n"
            sim.call(sim.plc.write, "CIO 0.00", [0])
            assert re.fullmatch(rf"part {part} out after \d+\.\d\d s\n", proc.stdout.readline())
    finally:
        proc.kill()
        proc.wait()


def test_the_examples_are_in_the_readme() -> None:
    readme = (ROOT / "README.md").read_text()
    assert "docs/examples.md" in readme
