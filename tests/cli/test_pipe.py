"""A reader that stops reading (``aiofins poll … | head``) ends the command quietly."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "args",
    [
        ["poll", "--interval", "0.001", "--count", "0", "D0", "D1"],
        ["read", "D0", "5000"],
    ],
    ids=["poll", "read"],
)
def test_a_closed_pipe_ends_the_command_with_sigpipe_s_exit_code_and_no_message(
    url: str, args: list[str]
) -> None:
    # ``read D0 5000`` prints more than a pipe holds, so both commands write after the
    # reader has gone, whatever the scheduling.
    command, *rest = args
    proc = subprocess.Popen(
        [sys.executable, "-m", "aiofins.cli", command, url, *rest],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline()
    proc.stdout.close()  # what ``head -1`` does after its line
    stderr = proc.stderr.read()
    assert proc.wait(timeout=60) == 141
    assert first.strip()
    assert stderr == b""
