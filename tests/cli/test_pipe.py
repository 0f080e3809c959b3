"""A reader that stops reading (``aiofins poll … | head``) ends the command quietly."""

from __future__ import annotations

import subprocess
import sys


def test_a_closed_pipe_ends_the_command_with_sigpipe_s_exit_code_and_no_message(url: str) -> None:
    # ``poll --count 0`` prints until stopped, so it writes after the reader has gone,
    # whatever the scheduling.
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "aiofins.cli",
            "poll",
            url,
            "D0",
            "D1",
            "--interval",
            "0.001",
            "--count",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # what ``head -1`` does after its line
    stderr = proc.stderr.read()
    assert proc.wait(timeout=60) == 141
    assert first.startswith(b"#1 ")
    assert stderr == b""
