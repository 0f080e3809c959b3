"""Library etiquette: aiofins logs, the application decides where records go."""

from __future__ import annotations

import logging
import socket
import subprocess
import sys

import pytest

import aiofins

SCRIPT = """
import anyio, aiofins

async def main():
    async with aiofins.connect("udp://127.0.0.1:{port}", timeout=0.2, retries=0) as plc:
        try:
            await plc.read("D0")
        except aiofins.FinsTimeout:
            print("handled")

anyio.run(main, backend={backend!r})
"""


def test_the_package_logger_has_a_null_handler_and_nothing_else() -> None:
    handlers = logging.getLogger("aiofins").handlers
    assert [type(h) for h in handlers] == [logging.NullHandler]


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_script_that_handles_a_timeout_prints_nothing_on_stderr(backend: str) -> None:
    """Without a NullHandler the session's WARNING about the unanswered request reached
    logging's last resort: on stderr of a script that had handled FinsTimeout itself."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # a PLC that never answers
        silent.bind(("127.0.0.1", 0))
        port = silent.getsockname()[1]
        result = subprocess.run(
            [sys.executable, "-c", SCRIPT.format(port=port, backend=backend)],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert result.returncode == 0, result.stderr
    assert result.stdout == "handled\n"
    assert result.stderr == ""


def test_an_application_that_configures_logging_still_gets_the_records(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING, logger="aiofins"):
        logging.getLogger("aiofins.session").warning("seen")
    assert [r.getMessage() for r in caplog.records] == ["seen"]
    assert aiofins.__version__
