"""The command line's write guard (#17 item 8) and its run/stop/clock --set commands (#15):
``--read-only`` refuses, a terminal is asked before a change unless ``--yes``, a script is not."""

from __future__ import annotations

import io
import json
import os
import pty
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from .test_cli import run, simulator_url


class Terminal:
    """stdin as a terminal where the user types ``answer`` (``None``: must not be asked)."""

    def __init__(self, answer: str | None) -> None:
        self.asked = 0
        self.answer = answer

    def isatty(self) -> bool:
        return True

    def readline(self) -> str:
        assert self.answer is not None, "the user was asked"
        self.asked += 1
        return self.answer


@pytest.fixture
def url() -> Iterator[str]:
    """A simulator of our own (these tests change its mode), in RUN mode."""
    with simulator_url() as url:
        yield url


def mode(capsys: pytest.CaptureFixture[str], url: str) -> str:
    code, out, _ = run(capsys, "status", url, "--json")
    assert code == 0
    return str(json.loads(out)["mode"])


def d0(capsys: pytest.CaptureFixture[str], url: str) -> list[int]:
    code, out, _ = run(capsys, "read", url, "D0", "--json")
    assert code == 0
    return list(json.loads(out)["values"])


def test_read_only_refuses_before_anything_is_sent(
    url: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys, "stdin", Terminal(None))  # refused, so nobody is asked
    for argv in (
        ("write", url, "D0", "5"),
        ("stop", url),
        ("run", url, "--mode", "run"),
        ("clock", url, "--set", "2026-01-02T03:04:05"),
        ("files", url, "delete", "A.TXT"),
    ):
        code, out, err = run(capsys, *argv, "--read-only")
        assert code == 1 and out == "" and "ReadOnlyError: read-only client" in err, err
    code, out, err = run(capsys, "write", url + "?read_only=1", "D0", "5", "--yes")
    assert code == 1 and "ReadOnlyError" in err
    assert d0(capsys, url) == [0] and mode(capsys, url) == "RUN"
    assert run(capsys, "read", url, "D0", "--read-only")[0] == 0  # reads still work


def test_a_terminal_is_asked_and_no_means_nothing_is_sent(
    url: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    image = tmp_path / "program.bin"
    assert run(capsys, "backup", url, str(image))[0] == 0
    for argv in (
        ("write", url, "D0", "5"),
        ("stop", url),
        ("restore", url, str(image), "--stop"),
        ("files", url, "delete", "A.TXT"),
        ("clock", url, "--set", "2001-01-01T00:00:00"),
    ):
        terminal = Terminal("n\n")
        monkeypatch.setattr(sys, "stdin", terminal)
        code, out, err = run(capsys, *argv)
        assert terminal.asked == 1
        assert code == 1 and out == "" and "not confirmed, nothing sent" in err, err
        assert "[y/N]" in err and url in err
    monkeypatch.setattr(sys, "stdin", io.StringIO())  # not a terminal: not asked
    assert d0(capsys, url) == [0] and mode(capsys, url) == "RUN"
    code, out, _ = run(capsys, "clock", url, "--json")
    assert not json.loads(out)["time"].startswith("2001")

    monkeypatch.setattr(sys, "stdin", Terminal("y\n"))
    assert run(capsys, "write", url, "D0", "5")[0] == 0
    monkeypatch.setattr(sys, "stdin", Terminal(None))
    assert run(capsys, "write", url, "D0", "6", "--yes")[0] == 0
    monkeypatch.setattr(sys, "stdin", io.StringIO())
    assert d0(capsys, url) == [6]


def test_restore_in_run_mode_says_what_to_type(
    url: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Not 'client.stop()': a command-line user is told about --stop."""
    monkeypatch.setattr(sys, "stdin", io.StringIO())
    image = tmp_path / "program.bin"
    assert run(capsys, "backup", url, str(image))[0] == 0
    code, out, err = run(capsys, "restore", url, str(image))
    assert code == 1 and out == "" and "needs PROGRAM mode: add --stop" in err, err
    assert "client.stop()" not in err
    assert run(capsys, "restore", url, str(image), "--stop")[0] == 0
    assert mode(capsys, url) == "PROGRAM"


@pytest.mark.parametrize(("answer", "code"), [(b"n\n", 1), (b"yes\n", 0)])
def test_a_real_terminal_is_asked(
    url: str, capsys: pytest.CaptureFixture[str], answer: bytes, code: int
) -> None:
    """``aiofins stop`` in its own process with a pseudo-terminal as stdin."""
    controller, terminal = pty.openpty()
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "aiofins", "stop", url],
            stdin=terminal,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        os.write(controller, answer)
        _, err = proc.communicate(timeout=30)
    finally:
        os.close(controller)
        os.close(terminal)
    assert proc.returncode == code and b"(switch it to PROGRAM mode)? [y/N]" in err
    assert mode(capsys, url) == ("RUN" if code else "PROGRAM")


def test_run_stop_and_clock_set(
    url: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Scripts (no terminal on stdin) are not asked: they keep working as before."""
    monkeypatch.setattr(sys, "stdin", io.StringIO())
    code, out, _ = run(capsys, "stop", url, "--json")
    assert code == 0 and json.loads(out) == {"mode": "PROGRAM"}
    assert mode(capsys, url) == "PROGRAM"
    assert run(capsys, "run", url)[0] == 0
    assert mode(capsys, url) == "MONITOR"
    assert run(capsys, "run", url, "--mode", "run") == (0, "mode: RUN\n", "")
    assert mode(capsys, url) == "RUN"
    code, out, _ = run(capsys, "clock", url, "--set", "2026-01-02T03:04:05", "--json")
    assert code == 0 and json.loads(out)["time"].startswith("2026-01-02T03:04:0")
    code, out, err = run(capsys, "clock", url, "--set", "yesterday")
    assert code == 1 and "give an ISO time" in err
    assert run(capsys, "clock", url, "--set")[0] == 0  # this computer's time
