"""``aiofins watch``: what it puts on a terminal's screen (run under a pseudo-terminal, its
output fed to a terminal emulator), and the sparkline and trend behind the trend column."""

from __future__ import annotations

import fcntl
import io
import os
import signal
import struct
import subprocess
import sys
import termios
from collections.abc import Callable

import pyte
import pytest

from aiofins.cli.watch import BARS, GAP, Trend, render, sparkline, trend_width
from aiofins.poller import Quality, Snapshot, TagReading
from aiofins.protocol.errors import CommandError
from aiofins.simulator import Mode, VirtualPLC
from tests.simulated import ROOT, simulated_plc

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX pseudo-terminals")


def test_sparkline_scales_between_the_lowest_and_the_highest_value() -> None:
    assert sparkline([0, 7, 14]) == BARS[0] + BARS[4] + BARS[7]
    assert sparkline([5.0, None, 5.0]) == BARS[3] + GAP + BARS[3]  # flat: mid height
    assert sparkline([None, None]) == GAP * 2
    assert sparkline([False, True]) == BARS[0] + BARS[-1]


def _snap(scan: int, **readings: TagReading) -> Snapshot:
    return Snapshot("watch", "udp://plc", scan, float(scan), 0.001, readings, frozenset(readings))


def test_a_trend_keeps_its_length_and_a_gap_where_a_scan_did_not_read_the_tag() -> None:
    trend = Trend(["t", "s"], 3)
    good, stale = Quality.GOOD, Quality.STALE
    for scan, (t, q) in enumerate([(1.0, good), (9.0, good), (9.0, stale), (5.0, good)], 1):
        trend.add(_snap(scan, t=TagReading(t, q, float(scan)), s=TagReading("x", good, 1.0)))
    assert trend.line("t") == BARS[-1] + GAP + BARS[0]  # 9, (stale), 5: the 1 has scrolled off
    assert trend.range("t") == (5.0, 9.0)
    assert trend.line("s") == GAP * 3 and trend.range("s") is None  # a string has no trend
    with pytest.raises(CommandError, match="--history 0"):
        Trend(["t"], 0)


def test_a_narrow_terminal_shortens_the_trend_not_the_names_and_values() -> None:
    from rich.console import Console

    tags = {"temperature_oven_1": "D100:float32", "run": "CIO 0.00"}
    trend = Trend(list(tags), 40)
    for scan in range(1, 41):  # a ramp: the latest scans are the highest
        readings = {
            "temperature_oven_1": TagReading(float(scan), Quality.GOOD, 1.0),
            "run": TagReading(scan % 2 == 0, Quality.GOOD, 1.0),
        }
        trend.add(_snap(scan, **readings))
    screen = io.StringIO()
    console = Console(file=screen, width=72, color_system=None)
    console.print(render("udp://plc", tags, _snap(40, **readings), trend, 72))
    (row,) = [line for line in screen.getvalue().splitlines() if line.startswith("temperature")]
    cells = row.split()
    assert cells[:4] == ["temperature_oven_1", "D100:float32", "40", "good"]
    assert cells[-2:] == ["1", "40"] and len(row) <= 72
    shown = trend_width([[*row.split()[:4], "", "1", "40"]], 72, 40)
    assert 1 < shown < 40 and cells[4] == sparkline([float(v) for v in range(41 - shown, 41)])


class Terminal:
    """A command run on a pseudo-terminal of ``rows`` x ``cols``, its output shown on a
    terminal emulator's screen."""

    def __init__(self, argv: list[str], env: dict[str, str], rows: int = 24, cols: int = 110):
        self.screen = pyte.Screen(cols, rows)
        self.stream = pyte.ByteStream(self.screen)
        self.master, slave = os.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
        env = {**env, "TERM": "xterm-256color"}
        for name in ("COLUMNS", "LINES", "NO_COLOR", "FORCE_COLOR", "TERM_PROGRAM"):
            env.pop(name, None)
        self.proc = subprocess.Popen(
            argv, stdin=slave, stdout=slave, stderr=slave, env=env, cwd=ROOT,
            start_new_session=True,
        )  # fmt: skip
        os.close(slave)  # the child's end: reading the master fails once the child is gone

    def lines(self) -> list[str]:
        return [line.rstrip() for line in self.screen.display]

    def row(self, name: str) -> list[str]:
        """The cells of the table row of tag ``name`` (split on runs of spaces)."""
        for line in self.lines():
            if line.startswith(f"{name} "):
                return line.split()
        return []

    def wait_for(self, ready: Callable[[], bool]) -> None:
        """Read the command's output until the screen shows what ``ready`` looks for."""
        while not ready():
            try:
                data = os.read(self.master, 65536)
            except OSError:  # EIO: the command has exited
                data = b""
            if not data:
                raise AssertionError("the command ended first; screen:\n" + "\n".join(self.lines()))
            self.stream.feed(data)

    def stop(self) -> int:
        """Ctrl-C, as a terminal sends it (SIGINT); the rest of the output; the exit code."""
        self.proc.send_signal(signal.SIGINT)
        while True:
            try:
                data = os.read(self.master, 65536)
            except OSError:
                break
            if not data:
                break
            self.stream.feed(data)
        os.close(self.master)
        return self.proc.wait()


def _watch(url: str, *args: str) -> list[str]:
    return [sys.executable, "-m", "aiofins", "watch", url, *args]


def test_watch_shows_each_tag_with_its_value_quality_and_trend() -> None:
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as sim:
        sim.call(sim.plc.write_value, "D100", 20.0, "float32")
        sim.call(sim.plc.write_value, "D110", "LOT-7", "string:8")
        tags = ["temp=D100:float32", "run=CIO 0.00", "lot=D110:string:8"]
        term = Terminal(_watch(sim.url, *tags, "--interval", "0.05", "--count", "5000"), sim.env())
        try:
            # A frame can take several reads to arrive: wait until it is all on the screen.
            term.wait_for(
                lambda: (
                    term.row("temp")[2:4] == ["20", "good"]
                    and term.row("run")[:4] == ["run", "CIO", "0.00", "False"]
                    and term.row("lot")[:4] == ["lot", "D110:string:8", "LOT-7", "good"]
                    and "Ctrl-C to stop" in term.lines()
                )
            )
            header = next(line for line in term.lines() if line.startswith("aiofins watch"))
            assert f"aiofins watch {sim.url}   scan" in header
            # The process moves: the value, its trend and its range follow.
            sim.call(sim.plc.write_value, "D100", 80.0, "float32")
            sim.call(sim.plc.write, "CIO 0.00", [1])
            term.wait_for(lambda: term.row("temp")[2:3] == ["80"])
            temp = term.row("temp")
            assert temp[-2:] == ["20", "80"]  # min, max over the trend
            assert temp[4].startswith(BARS[0]) and temp[4].endswith(BARS[-1]), temp
            term.wait_for(lambda: term.row("run")[3:4] == ["True"])
        finally:
            code = term.stop()
        assert code == 0, "\n".join(term.lines())
        assert "Traceback" not in "\n".join(term.lines())


def test_watch_says_when_the_plc_stops_answering() -> None:
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as sim:
        argv = _watch(sim.url, "D0", "--interval", "0.05", "--timeout", "0.2", "--count", "5000")
        term = Terminal(argv, sim.env())
        try:
            term.wait_for(lambda: term.row("D0")[3:4] == ["good"])
            sim.go_silent()
            term.wait_for(lambda: term.row("D0")[3:4] == ["stale"])
            assert any("no response to command 0101" in line for line in term.lines())
        finally:
            code = term.stop()
        assert code == 0, "\n".join(term.lines())


def test_watch_without_rich_names_the_extra() -> None:
    code = (
        "import sys; sys.modules['rich'] = None; from aiofins.cli import main; "
        "sys.exit(main(['watch', 'udp://127.0.0.1:1', 'D0']))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 1
    assert "pip install -e '.[watch]'" in result.stderr and "Traceback" not in result.stderr
