"""Shared test configuration: async tests run under asyncio, uvloop and trio via anyio."""

from __future__ import annotations

import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

from aiofins.simulator.serial import SerialSettings

# Hypothesis' per-example deadline (200 ms by default) is a wall-clock bound: under a busy
# machine an example that runs in 24 ms alone took 560 ms and failed the suite
# (tests/helpers/test_chunking.py, README's test command beside six busy processes). Tests
# assert bytes and values, never time, so no example has a deadline.
settings.register_profile("aiofins", deadline=None)
settings.load_profile("aiofins")

#: A pty takes only 8N1 (tcsetattr refuses 7E2, the default of the client and simulator):
#: the client URL's options and the simulator's settings that tests on ptys pin.
PTY_8N1 = "bytesize=8&parity=N&stopbits=1"
PTY_LINE = SerialSettings(bytesize=8, parity="N", stopbits=1)


def pytest_configure(config: pytest.Config) -> None:
    """SIGINT as a terminal's foreground program has it, for the programs tests stop with it.

    A script that runs the suite as a background job (``pytest &`` in a non-interactive shell)
    starts it with SIGINT ignored, and every program a test starts would inherit that: Python
    then installs no KeyboardInterrupt, and a script stopped by SIGINT (Ctrl-C, as a user
    stops ``examples/watch_alarms.py``) never ends. The suite takes SIGINT's default back.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


#: An anyio backend: a name, or a name and its options.
Backend = str | tuple[str, dict[str, Any]]


@pytest.fixture(
    params=[
        "asyncio",
        pytest.param(("asyncio", {"use_uvloop": True}), id="uvloop"),
        "trio",
    ]
)
def anyio_backend(request: pytest.FixtureRequest) -> Backend:
    """Every async test runs under stock asyncio, asyncio with uvloop, and trio."""
    backend: Backend = request.param
    if backend != "asyncio" and backend != "trio":
        pytest.importorskip("uvloop")
    return backend


@pytest.fixture
def pty_pair(tmp_path: Path) -> Iterator[tuple[str, str]]:
    """Two linked pseudo-terminals made by socat (8N1, raw): (plc side, host side)."""
    if shutil.which("socat") is None:
        pytest.skip("socat is not installed (apt-get install socat)")
    a, b = tmp_path / "plc", tmp_path / "host"
    proc = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 5
        while not (a.exists() and b.exists()):  # socat makes both links within milliseconds
            if time.monotonic() > deadline:
                pytest.fail("socat did not create the pty pair within 5 s")
            time.sleep(0.005)
        yield str(a), str(b)
    finally:
        proc.terminate()
        proc.wait(timeout=5)
