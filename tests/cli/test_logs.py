"""``aiofins -v/-vv`` and ``--log-format json`` against ``aiofins simulate`` (a real process)."""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator

import pytest

from aiofins.cli import main

from ..client.test_cli import simulator_url


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    with simulator_url() as url:
        yield url


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[str, list[str]]:
    assert main(list(argv)) == 0
    out, err = capsys.readouterr()
    return out, err.splitlines()


def test_quiet_by_default(url: str, capsys: pytest.CaptureFixture[str]) -> None:
    out, err = run(capsys, "read", url, "D0")
    assert "D0" in out and err == []


def test_cpu_error_flags_are_said_once_without_v(capsys: pytest.CaptureFixture[str]) -> None:
    """The command warns about them itself; the session's log warning shows with -v."""
    with simulator_url("--flags", "40") as url:
        _, err = run(capsys, "read", url, "D0")
        (warning,) = err
        assert "warning: the PLC reports a non-fatal CPU error (end code 0040)" in warning
        _, err = run(capsys, "-v", "read", url, "D0")
        assert any(
            line.endswith(
                f"WARNING aiofins.session: {url} reports a non-fatal CPU error "
                "(end code 0040 flag 0040); see the CPU's error log"
            )
            for line in err
        )


def test_v_logs_the_lifecycle(url: str, capsys: pytest.CaptureFixture[str]) -> None:
    _, err = run(capsys, "-v", "read", url, "D0")
    assert any(line.endswith(f"INFO aiofins.session: connected to {url}") for line in err)
    assert not any(" DEBUG " in line for line in err)


def test_vv_logs_every_frame_as_json(url: str, capsys: pytest.CaptureFixture[str]) -> None:
    # The options work after the subcommand too.
    out, err = run(capsys, "read", url, "D0", "2", "-vv", "--log-format", "json")
    assert "D0" in out and "aiofins" not in out  # logs go to stderr only
    records = [json.loads(line) for line in err]
    frames = [r for r in records if r.get("command") == "0101"]
    sent, received = frames
    assert sent["level"] == received["level"] == "DEBUG"
    assert sent["logger"] == "aiofins.session" and sent["endpoint"] == url
    assert sent["sid"] == received["sid"]
    assert sent["message"].endswith(f"{sent['sid']:02x} 01 01 82 00 00 00 00 02")
    assert received["message"].endswith(f"{sent['sid']:02x} 01 01 00 00 00 00 00 00")
    assert {"time", "level", "logger", "message"} <= set(records[0])


def test_the_logger_is_left_as_it_was(url: str, capsys: pytest.CaptureFixture[str]) -> None:
    logger = logging.getLogger("aiofins")
    handlers, level = list(logger.handlers), logger.level
    run(capsys, "-vv", "read", url, "D0")
    assert logger.handlers == handlers and logger.level == level
