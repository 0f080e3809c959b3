"""PLC text in the command line's human output: control characters shown, never sent raw.

A simulator whose file names, FAL message, model and memory hold ESC sequences serves the
commands (in a portal thread, under each anyio backend); the command line runs as the user
runs it, and nothing it prints may carry an ESC (or another control character) to the terminal.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from anyio.from_thread import start_blocking_portal
from hypothesis import given
from hypothesis import strategies as st

from aiofins.cli import main, report
from aiofins.cli.text import escape
from aiofins.protocol.errors import FinsError
from aiofins.protocol.files import Disk, FileWriteMode
from aiofins.simulator import VirtualPLC, run_simulator

#: Clear the screen, then a red line: what a hostile or broken PLC could send.
CLEAR = "\x1b[2J"
FILE_NAME = "\x1b[2J\x1b[31mX"
FAL_MESSAGE = "\x1b]0;owned\x07 OK"
MODEL = "CJ2M\x1b[5m"  # blinking from here on


@pytest.fixture
def hostile_url(anyio_backend: Any) -> Iterator[str]:
    backend, options = (anyio_backend, {}) if isinstance(anyio_backend, str) else anyio_backend
    plc = VirtualPLC(model=MODEL)
    plc.file_memory[Disk.MEMORY_CARD].write((), FILE_NAME, FileWriteMode.NEW, 0, b"x" * 5)
    plc.raise_error(0x4101, message=FAL_MESSAGE)  # a non-fatal FAL error with its message
    text = (CLEAR + "ab").encode("ascii")
    plc.memory.write_words(0x82, 0, [int.from_bytes(text[i : i + 2], "big") for i in (0, 2, 4)])
    with (
        start_blocking_portal(backend, options) as portal,
        portal.wrap_async_context_manager(run_simulator(plc, udp=("127.0.0.1", 0))) as sim,
    ):
        yield f"udp://127.0.0.1:{sim.udp_port}"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def no_controls(text: str) -> bool:
    return all(c.isprintable() or c == "\n" for c in text)


def test_files_list_status_info_and_read_escape_plc_text(
    hostile_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(capsys, "files", hostile_url, "list")
    assert code == 0 and no_controls(out + err)
    assert "\\x1b[2J\\x1b[31mX" in out
    code, out, err = run(capsys, "status", hostile_url)
    assert code == 0 and no_controls(out + err)
    assert "error_message: \\x1b]0;owned\\x07 OK" in out
    code, out, err = run(capsys, "info", hostile_url)
    assert code == 0 and no_controls(out + err)
    assert "CJ2M\\x1b[5m" in out
    code, out, err = run(capsys, "read", hostile_url, "D0", "--type", "string:6")
    assert code == 0 and no_controls(out + err)
    assert "values: \\x1b[2Jab" in out
    code, out, err = run(capsys, "poll", hostile_url, "s=D0:string:6", "--count", "1")
    assert code == 0 and no_controls(out + err)
    assert "s=\\x1b[2Jab" in out


def test_json_output_keeps_the_text_exact_and_escaped(
    hostile_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run(capsys, "files", hostile_url, "list", "--json")
    assert code == 0 and no_controls(out)
    assert FILE_NAME in [entry["name"] for entry in json.loads(out)]
    code, out, _ = run(capsys, "status", hostile_url, "--json")
    assert code == 0 and no_controls(out)
    assert json.loads(out)["error_message"] == FAL_MESSAGE


def test_error_messages_are_escaped(capsys: pytest.CaptureFixture[str]) -> None:
    assert report("aiofins", FinsError(f"file {FILE_NAME} refused"), (FinsError,))
    err = capsys.readouterr().err
    assert err == "aiofins: FinsError: file \\x1b[2J\\x1b[31mX refused\n"


@pytest.mark.parametrize(
    ("text", "shown"),
    [
        ("plain text, é ü ñ, 温度", "plain text, é ü ñ, 温度"),
        ("\x1b[31mred", "\\x1b[31mred"),
        ("a\r\nb\tc\x00\x7f", "a\\x0d\\x0ab\\x09c\\x00\\x7f"),
        ("\x9b31m", "\\x9b31m"),  # C1 CSI: one byte does what ESC [ does on some terminals
        ("abc\u202edef", "abc\\u202edef"),  # right-to-left override
        ("\U000e0041", "\\U000e0041"),  # a tag character
        (7, "7"),
    ],
)
def test_escape(text: object, shown: str) -> None:
    assert escape(text) == shown


@given(st.text())
def test_escape_leaves_nothing_a_terminal_acts_on(text: str) -> None:
    shown = escape(text)
    assert shown.isprintable()
    if text.isprintable():
        assert shown == text
