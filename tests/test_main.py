"""``python -m aiofins`` is the ``aiofins`` command line."""

from __future__ import annotations

import subprocess
import sys

import aiofins


def test_python_m_aiofins_runs_the_command_line() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "aiofins", "--version"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0 and done.stdout.strip() == f"aiofins {aiofins.__version__}"
    done = subprocess.run(
        [sys.executable, "-m", "aiofins", "read", "udp://127.0.0.1:1", "D0", "--timeout", "nan"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2
    assert "timeout must be a positive number of seconds; got 'nan'" in done.stderr
