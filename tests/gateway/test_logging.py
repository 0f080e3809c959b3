"""The gateway daemon's log, captured from the real CLI (a subprocess) against a real
Mosquitto and a virtual PLC: INFO by default, one handler, each record once, one format."""

from __future__ import annotations

import json
import signal
import sys
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import anyio.abc
import pytest

from aiofins.simulator import VirtualPLC, run_simulator

from .conftest import Broker, publisher, subscribe

pytestmark = pytest.mark.anyio


class Daemon:
    """``aiofins gateway`` in a subprocess; :meth:`until` reads its stderr lines."""

    def __init__(self, process: anyio.abc.Process) -> None:
        self.process = process
        self.lines: list[str] = []
        self._buffer = b""

    async def until(self, condition: Callable[[str], bool]) -> str:
        """The first line of stderr that meets ``condition`` (read until one does)."""
        assert self.process.stderr is not None
        for line in self.lines:
            if condition(line):
                return line
        with anyio.move_on_after(30):  # a guard against a hang, not a timing bound
            while True:
                while b"\n" in self._buffer:
                    raw, self._buffer = self._buffer.split(b"\n", 1)
                    line = raw.decode()
                    self.lines.append(line)
                    if condition(line):
                        return line
                try:
                    self._buffer += await self.process.stderr.receive()
                except anyio.EndOfStream:
                    raise AssertionError(f"the daemon ended: {self.lines}") from None
        raise AssertionError(f"no such line in {self.lines} {self._buffer!r}")

    async def stop_exited(self) -> list[str]:
        """Every line of a process that ended on its own."""
        assert self.process.stderr is not None
        with anyio.fail_after(30):
            try:
                while True:
                    self._buffer += await self.process.stderr.receive()
            except (anyio.EndOfStream, anyio.ClosedResourceError):
                pass
        self.lines += [line.decode() for line in self._buffer.split(b"\n") if line]
        self._buffer = b""
        return self.lines

    async def stop(self) -> list[str]:
        """SIGTERM, then the rest of its stderr; every line it wrote."""
        assert self.process.stderr is not None
        self.process.send_signal(signal.SIGTERM)
        with anyio.fail_after(30):
            try:
                while True:
                    self._buffer += await self.process.stderr.receive()
            except (anyio.EndOfStream, anyio.ClosedResourceError):
                pass
            assert await self.process.wait() == 0
        self.lines += [line.decode() for line in self._buffer.split(b"\n") if line]
        self._buffer = b""
        return self.lines


@asynccontextmanager
async def daemon(broker: Broker, tmp_path: Path, *options: str) -> AsyncIterator[Daemon]:
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
        config = tmp_path / "gw.toml"
        config.write_text(
            f"""
[gateway]
name = "logs"
[mqtt]
port = {broker.port}
[http]
enabled = false
[[groups]]
name = "g"
interval = 0.2
tags = {{ sp = "D100:int16" }}
writable = ["sp"]
[[plcs]]
name = "p1"
url = "udp://127.0.0.1:{sim.udp_port}"
"""
        )
        argv = [sys.executable, "-m", "aiofins.cli", "gateway", str(config), *options]
        async with await anyio.open_process(argv) as process:
            d = Daemon(process)
            assert process.stdout is not None
            with anyio.fail_after(30):  # the signal handlers are in place once it says so
                said = await process.stdout.receive()
            assert said.startswith(b"gateway logs: 1 PLCs"), said
            try:
                yield d
            finally:
                if process.returncode is None:
                    process.kill()


def connected(line: str) -> bool:
    return "MQTT link CONNECTING -> CONNECTED" in line


async def test_info_by_default_each_record_once_with_a_line_per_write(
    broker: Broker, tmp_path: Path
) -> None:
    """Before: nothing below ERROR was logged (the shared handler's ERROR won over the
    gateway's basicConfig), and with -v each line came twice."""
    async with daemon(broker, tmp_path) as d:
        await d.until(connected)
        await d.until(lambda line: "PLC p1 is online" in line)
        async with (
            subscribe(broker.port, "fins/p1/g/set/sp/reply") as sub,
            publisher(broker.port) as pub,
        ):
            await pub.publish("fins/p1/g/set/sp", '{"value": 7, "id": "w1"}', qos=1)
            written = await d.until(lambda line: "set p1/g/sp = 7" in line)
            await sub.wait_for(lambda: sub.messages)
        lines = await d.stop()
    assert " INFO aiofins.gateway: set p1/g/sp = 7" in written
    assert not any(line.startswith("{") for line in lines)
    assert len(lines) == len(set(lines)), "a record printed twice"
    assert sum(connected(line) for line in lines) == 1
    assert any("MQTT link CONNECTED -> CLOSED" in line for line in lines)


async def test_v_and_json_print_each_record_once_as_json(broker: Broker, tmp_path: Path) -> None:
    async with daemon(broker, tmp_path, "-v", "--log-format", "json") as d:
        await d.until(connected)
        lines = await d.stop()
    records = [json.loads(line) for line in lines]  # every line is JSON: no text copy
    messages = [r["message"] for r in records]
    assert len(messages) == len(set(messages))
    assert any(r["level"] == "INFO" and r["logger"] == "aiofins.gateway" for r in records)


async def test_log_level_debug_takes_effect_and_wins_over_v(broker: Broker, tmp_path: Path) -> None:
    """Before: ``--log-level DEBUG`` changed nothing."""
    async with daemon(broker, tmp_path, "--log-level", "debug") as d:
        await d.until(lambda line: " DEBUG " in line)
        # Once its PLC was scanned, the daemon froze what it holds (full collections skip it).
        await d.until(lambda line: " DEBUG aiofins.gateway: " in line and "objects frozen" in line)
        await d.stop()
    async with daemon(broker, tmp_path, "-vv", "--log-level", "WARNING") as d:
        lines = await d.stop()
    assert not any(" INFO " in line or " DEBUG " in line for line in lines), lines
