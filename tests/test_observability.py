"""Logging and event hooks on real loopback runs against the simulator, faults injected.

Every log line and hook event the library promises (docs/observability.md) is asserted here
(those that depend on how much time passes on virtual time, under asyncio and trio):
real ``logging`` loggers captured with ``caplog``, hooks given to ``connect()``, ``Pool`` and
``Poller``; drops, late replies, CPU error flags, a PLC that goes away and comes back.
"""

from __future__ import annotations

import logging
import re
import socket
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import anyio
import pytest
from anyio.abc import TaskStatus

import aiofins
from aiofins.hooks import (
    ConnectionStateChanged,
    EventHooks,
    RequestRetried,
    RequestSent,
    RequestTimedOut,
    ResponseReceived,
    ScanDone,
)
from aiofins.poller import Poller
from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.simulator.faults import Delay, FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator
from aiofins.transport import UdpTransport

from .virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio

PLC = FinsAddress(0, 1, 0)


class Recorder:
    """Every event of every hook, in order."""

    def __init__(self) -> None:
        self.events: list[object] = []
        record: Callable[[object], None] = self.events.append
        self.hooks = EventHooks(
            request_sent=[record],
            response_received=[record],
            request_retried=[record],
            request_timed_out=[record],
            connection_state_changed=[record],
            scan_done=[record],
        )

    def of(self, kind: type[Any]) -> list[Any]:
        return [e for e in self.events if isinstance(e, kind)]


@asynccontextmanager
async def simulator(*, tcp_port: int | None = None) -> AsyncIterator[Simulator]:
    async with run_simulator(
        VirtualPLC(),
        udp=("127.0.0.1", 0),
        tcp=("127.0.0.1", 0 if tcp_port is None else tcp_port),
        faults=FaultPlan(seed=3),
    ) as sim:
        yield sim


def records(
    caplog: pytest.LogCaptureFixture, name: str, level: int | None = None
) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == name and (level is None or r.levelno == level)]


def messages(caplog: pytest.LogCaptureFixture, name: str, level: int) -> list[str]:
    return [r.getMessage() for r in records(caplog, name, level)]


@on_virtual_time
async def test_a_request_logs_its_frames_and_emits_sent_and_received(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="aiofins")
    rec = Recorder()
    async with simulator() as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        # retries=0: one transmission each, however loaded the machine.
        async with aiofins.connect(url, dest="0.1.0", hooks=rec.hooks, retries=0) as plc:
            await plc.write("D100", [0x1234])
            assert await plc.read("D100", 1) == [0x1234]
    sent = rec.of(RequestSent)
    received = rec.of(ResponseReceived)
    assert [e.command_code for e in sent] == [0x0102, 0x0101]
    assert [e.command_code for e in received] == [0x0102, 0x0101]
    read_sent, read_reply = sent[1], received[1]
    assert read_sent.endpoint == url and read_sent.dest == PLC
    assert read_reply.sid == read_sent.sid and read_reply.end_code == 0
    assert read_reply.attempts == 1 and read_reply.elapsed == 0.0  # answered at once
    states = [(e.old, e.new) for e in rec.of(ConnectionStateChanged)]
    assert states == [("CLOSED", "CONNECTING"), ("CONNECTING", "OPEN"), ("OPEN", "SHUT")]

    session_log = records(caplog, "aiofins.session", logging.DEBUG)
    frames = [r for r in session_log if getattr(r, "command", None) == "0101"]
    assert [r.getMessage().split(": ")[1].split()[0] for r in frames] == ["sent", "received"]
    sid = read_sent.sid
    assert all(r.sid == sid and r.endpoint == url for r in frames)  # type: ignore[attr-defined]
    # The bytes in hex: the command's SID and code, the reply's data word.
    assert f"{sid:02x} 01 01 82 00 64 00 00 01" in frames[0].getMessage()
    assert frames[1].getMessage().endswith(f"{sid:02x} 01 01 00 00 12 34")
    info = messages(caplog, "aiofins.session", logging.INFO)
    assert f"connected to {url}" in info and f"session to {url} closed" in info
    assert all(r.endpoint == url for r in records(caplog, "aiofins.session"))  # type: ignore[attr-defined]
    simulator_info = messages(caplog, "aiofins.simulator.runner", logging.INFO)
    assert simulator_info[0].startswith("virtual PLC serving on udp://127.0.0.1:")


async def test_without_debug_no_frame_is_formatted(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="aiofins")
    async with (
        simulator() as sim,
        aiofins.connect(f"udp://127.0.0.1:{sim.udp_port}", dest="0.1.0") as plc,
    ):
        await plc.read("D0", 1)
    assert not [r for r in caplog.records if r.levelno < logging.INFO]
    assert records(caplog, "aiofins.session", logging.INFO)


@on_virtual_time
async def test_dropped_requests_retry_time_out_and_warn_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="aiofins")
    rec = Recorder()
    async with simulator() as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        async with aiofins.connect(
            url, dest="0.1.0", hooks=rec.hooks, timeout=0.3, retries=1
        ) as plc:
            sim.plan.rule = FaultRule(drop_request=1.0)
            for _ in range(3):
                with pytest.raises(aiofins.FinsTimeout):
                    await plc.read("D0", 1)
            sim.plan.rule = FaultRule()
            assert await plc.read("D0", 1) == [0]
            sim.plan.rule = FaultRule(drop_request=1.0)
            with pytest.raises(aiofins.FinsTimeout):
                await plc.read("D0", 1)
    timed_out = rec.of(RequestTimedOut)
    retried = rec.of(RequestRetried)  # on virtual time: the answered read went out once
    assert [e.attempt for e in retried] == [2, 2, 2, 2]
    assert [e.attempts for e in timed_out] == [2, 2, 2, 2]
    sent = rec.of(RequestSent)
    assert [e.sid for e in retried] == [e.sid for e in timed_out]
    assert {e.sid for e in timed_out} <= {e.sid for e in sent}
    assert all(e.command_code == 0x0101 and e.endpoint == url for e in timed_out)
    assert [e.elapsed for e in timed_out] == [pytest.approx(0.3, abs=1e-6)] * 4  # the timeout
    # A WARNING for the first call without an answer after an answered one, not for each.
    warnings = records(caplog, "aiofins.session", logging.WARNING)
    no_reply = [r for r in warnings if "no reply from 0.1.0" in r.getMessage()]
    assert len(no_reply) == 2
    first = no_reply[0]
    assert first.getMessage() == (
        f"{url}: no reply from 0.1.0 to SID {timed_out[0].sid} (command 0101) after "
        f"2 transmission(s) in {timed_out[0].elapsed:.3f} s"
    )
    assert (first.endpoint, first.node, first.sid, first.command) == (  # type: ignore[attr-defined]
        url,
        1,
        timed_out[0].sid,
        "0101",
    )


@on_virtual_time
async def test_late_replies_are_warned_about_when_they_repeat(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="aiofins.session")
    async with (
        simulator() as sim,
        aiofins.connect(
            f"udp://127.0.0.1:{sim.udp_port}", dest="0.1.0", timeout=0.05, retries=0
        ) as plc,
    ):
        sim.plan.rule = FaultRule(late=1.0, late_after=0.1)
        for _ in range(4):
            with pytest.raises(aiofins.FinsTimeout):
                await plc.read("D0", 1)
        sim.plan.rule = FaultRule()
        assert await plc.read("D0", 1) == [0]  # answered at once, before the last late one
        with anyio.fail_after(0.1):  # the last late reply comes 0.1 s after its request
            while plc.session.stats.late_replies < 4:
                await anyio.sleep(0.01)
    debug = messages(caplog, "aiofins.session", logging.DEBUG)
    assert sum("late reply for SID" in m for m in debug) == 2  # the 1st and the 3rd
    late = [m for m in messages(caplog, "aiofins.session", logging.WARNING) if "late" in m]
    assert [m.split(": ")[1].split(" late")[0] for m in late] == ["2", "4"]


async def test_cpu_error_flags_are_warned_about_once(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="aiofins")
    async with simulator() as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        async with aiofins.connect(url, dest="0.1.0") as plc:
            sim.plan.rule = FaultRule(flags=0x40)
            for _ in range(3):
                assert await plc.read("D0", 1) == [0]
            assert plc.session.stats.completed == 3
            sim.plan.rule = FaultRule(flags=0xC0)
            await plc.read("D0", 1)
            await plc.read("D0", 1)
    flags = messages(caplog, "aiofins.session", logging.WARNING)
    assert flags == [
        f"{url} reports a non-fatal CPU error (end code 0040 flag 0040); see the CPU's error log",
        f"{url} reports a fatal CPU error (end code 00C0 flag 0080); see the CPU's error log",
    ]


async def serve(port: int, stop: anyio.Event, *, task_status: TaskStatus[Simulator]) -> None:
    """A simulator on ``port`` (0: any) until ``stop`` is set."""
    async with simulator(tcp_port=port) as sim:
        task_status.started(sim)
        await stop.wait()


@on_virtual_time
async def test_a_plc_that_goes_away_and_comes_back(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="aiofins")
    rec = Recorder()
    async with anyio.create_task_group() as tg:
        gone = anyio.Event()
        first: Simulator = await tg.start(serve, 0, gone)
        port = first.tcp_port
        url = f"tcp://127.0.0.1:{port}"
        async with aiofins.connect(url, hooks=rec.hooks, timeout=3) as plc:
            assert await plc.read("D0", 1) == [0]
            node = plc.session.source.node
            gone.set()  # the PLC goes away with the connection open ...
            with anyio.fail_after(5):
                while plc.session.link_state.name == "OPEN":
                    await anyio.sleep(0.01)
            back = anyio.Event()
            await tg.start(serve, port, back)  # ... and comes back on the same port
            with anyio.fail_after(5):
                while True:
                    try:
                        assert await plc.read("D0", 1) == [0]
                        break
                    except aiofins.ConnectionLost:
                        await anyio.sleep(0.02)
            back.set()
    states = [(e.old, e.new) for e in rec.of(ConnectionStateChanged)]
    assert states[:3] == [("CLOSED", "CONNECTING"), ("CONNECTING", "OPEN"), ("OPEN", "CLOSED")]
    assert ("CONNECTING", "OPEN") in states[3:] and states[-1] == ("OPEN", "SHUT")
    assert all(e.endpoint == url for e in rec.of(ConnectionStateChanged))
    info = messages(caplog, "aiofins.session", logging.INFO)
    assert info[0] == f"{url} allocated us FINS node {node} (its own node: 1)"
    assert info[1] == f"connected to {url}"
    assert info[2].startswith(f"connection to {url} lost: ")
    reconnected = [m for m in info if m.startswith(f"reconnected to {url} after ")]
    assert len(reconnected) == 1 and reconnected[0].endswith(" s")
    sim_info = messages(caplog, "aiofins.simulator.tcp", logging.INFO)
    assert "FINS/TCP client 127.0.0.1:" in sim_info[0] and sim_info[0].endswith(
        f"connected as node {node}"
    )


@on_virtual_time
async def test_pool_and_poller_hooks_and_logs(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="aiofins")
    rec = Recorder()
    async with simulator() as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}?dest=0.1.0"
        async with (
            aiofins.Pool(hooks=rec.hooks, timeout=0.2, retries=0) as pool,
            Poller(pool) as poller,
        ):
            poller.add_group("line1", url, {"a": "D0", "b": "D1"}, interval=0.05)
            snapshots = aiter(poller)
            assert (await anext(snapshots)).error is None
            sim.plan.rule = FaultRule(drop_request=1.0)
            while (await anext(snapshots)).error is None:
                pass
            await anext(snapshots)  # a second failed scan: no second warning
            sim.plan.rule = FaultRule(delay=Delay(0.12, 0.12))  # longer than the interval
            while (await anext(snapshots)).error is not None:
                pass
            sim.plan.rule = FaultRule()
            await anext(snapshots)
    scans = rec.of(ScanDone)
    assert [e.scan for e in scans] == list(range(1, len(scans) + 1))
    assert all(e.group == "line1" and e.duration >= 0 for e in scans)
    failed = [e for e in scans if e.error is not None]
    assert len(failed) >= 2 and all(e.error.startswith("FinsTimeout: ") for e in failed)
    assert any(e.missed for e in scans)  # the slow scans skipped scan times
    # The pool's sessions emit the request events to the same hooks.
    assert rec.of(RequestSent) and rec.of(ResponseReceived) and rec.of(RequestTimedOut)
    assert {e.endpoint for e in rec.of(ResponseReceived)} == {f"udp://127.0.0.1:{sim.udp_port}"}
    poller_info = messages(caplog, "aiofins.poller", logging.INFO)
    # A scan that lets scan times pass while the PLC is silent or slow says what it waits for
    # (INFO, once per scan), instead of warning "cannot keep up" before its timeout.
    waiting = [m for m in poller_info if " waits for " in m]
    assert waiting and set(waiting) == {
        f"scan group line1: its scan waits for {url} to answer (timeout the endpoint's); "
        "scan times pass meanwhile (interval 0.05 s)"
    }
    poller_info = [m for m in poller_info if " waits for " not in m]
    assert poller_info[0] == f"scan group line1 started: 2 tags from {url} every 0.05 s"
    assert poller_info[1] == f"scan group line1: scans of {url} succeed again"
    assert poller_info[-1].startswith(f"scan group line1 stopped after {len(scans)} scans (")
    warnings = messages(caplog, "aiofins.poller", logging.WARNING)
    failing = [m for m in warnings if " fail: " in m]
    # The timeout is the first warning and counts the scan times that passed while it waited.
    assert len(failing) == 1
    assert re.fullmatch(
        re.escape(f"scan group line1: scans of {url} fail: {failed[0].error}")
        + r" \([1-9][0-9]* scan times? passed while it waited\)",
        failing[0],
    )
    missed = [m for m in warnings if " missed " in m]
    assert len(missed) == 1 and "interval 0.05 s" in missed[0]
    assert all(
        r.group == "line1"  # type: ignore[attr-defined]
        for r in records(caplog, "aiofins.poller")
    )


@on_virtual_time
async def test_pool_logs_an_entry_closed_idle(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="aiofins.pool")
    async with simulator() as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}?dest=0.1.0"
        async with aiofins.Pool(idle_timeout=0.05, health_interval=60) as pool:
            async with pool.client(url) as plc:
                await plc.read("D0", 1)
            with anyio.fail_after(5):
                while pool.stats(url)[next(iter(pool.stats(url)))].sessions:
                    await anyio.sleep(0.01)
    idle = [r for r in records(caplog, "aiofins.pool", logging.INFO) if "unused" in r.getMessage()]
    assert len(idle) == 1 and idle[0].getMessage().endswith(" s unused")
    assert idle[0].endpoint == idle[0].getMessage().split(": ")[0]  # type: ignore[attr-defined]


async def test_a_raising_hook_breaks_nothing(caplog: pytest.LogCaptureFixture) -> None:
    def boom(event: object) -> None:
        raise RuntimeError("hook bug")

    hooks = EventHooks(request_sent=[boom], response_received=[boom])
    async with (
        simulator() as sim,
        aiofins.connect(f"udp://127.0.0.1:{sim.udp_port}", dest="0.1.0", hooks=hooks) as plc,
    ):
        assert await plc.read("D0", 1) == [0]
    assert hooks.errors == 2
    assert len(records(caplog, "aiofins.hooks", logging.ERROR)) == 2


def session_to(sim: Simulator, **options: Any) -> Session:
    return Session(
        UdpTransport("127.0.0.1", sim.udp_port),
        source=FinsAddress(0, 254, 0),
        dest=PLC,
        **options,
    )


@on_virtual_time
async def test_sid_space_exhausted_is_warned_about_once(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="aiofins.session")
    async with simulator() as sim:
        sim.plan.rule = FaultRule(drop_request=1.0)
        session = session_to(
            sim,
            timeout=0.05,
            retries=0,
            max_in_flight=255,
            min_quarantine=60,
            breaker_threshold=0,
            max_sid_spaces=1,  # (one socket: its 256 SIDs are all there is)
        )
        async with session:

            async def read() -> None:
                with pytest.raises(aiofins.FinsTimeout):
                    await session.request(0x01, 0x01, bytes.fromhex("820000000001"))

            async with anyio.create_task_group() as tg:
                for _ in range(256):
                    tg.start_soon(read)
            for _ in range(2):  # all 256 SIDs quarantined: these wait for one, in vain
                await read()
            assert session.stats.sid_exhausted >= 1
    exhausted = [m for m in messages(caplog, "aiofins.session", logging.WARNING) if "SIDs" in m]
    assert exhausted == [
        f"udp://127.0.0.1:{sim.udp_port}: all 256 SIDs of 0.1.0 are taken (0 in flight, 256 "
        "quarantined, 0 lingering): requests wait for one; lower the rate or the linger"
    ]


@on_virtual_time
async def test_the_circuit_breaker_opening_and_closing_is_logged(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="aiofins.session")
    async with simulator() as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        session = session_to(sim, timeout=0.05, retries=0, breaker_threshold=3)
        async with session:
            sim.plan.rule = FaultRule(drop_request=1.0)
            for _ in range(3):
                with pytest.raises(aiofins.FinsTimeout):
                    await session.request(0x01, 0x01, bytes.fromhex("820000000001"))
            with pytest.raises(aiofins.CircuitOpen):
                await session.request(0x01, 0x01, bytes.fromhex("820000000001"))
            sim.plan.rule = FaultRule()
            with anyio.fail_after(5):
                while True:  # until the probe may go (the breaker's cooldown)
                    try:
                        await session.request(0x01, 0x01, bytes.fromhex("820000000001"))
                        break
                    except aiofins.CircuitOpen:
                        await anyio.sleep(0.01)
    warnings = messages(caplog, "aiofins.session", logging.WARNING)
    assert (
        f"{url}: 3 calls in a row got no answer: circuit breaker open, failing fast while "
        "a probe tests the link"
    ) in warnings
    assert f"{url} answers again: circuit breaker closed" in messages(
        caplog, "aiofins.session", logging.INFO
    )


async def test_a_refused_connection_is_warned_about(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="aiofins.session")
    with socket.socket() as unused:  # a port nobody listens on
        unused.bind(("127.0.0.1", 0))
        port = unused.getsockname()[1]
    url = f"tcp://127.0.0.1:{port}"
    with pytest.raises(aiofins.ConnectionLost):
        async with aiofins.connect(url, timeout=1) as plc:
            await plc.read("D0", 1)
    (warning,) = records(caplog, "aiofins.session", logging.WARNING)
    assert warning.getMessage().startswith(f"cannot connect to {url}: ")
    assert warning.getMessage().count(url) == 1
    assert "; next attempt in " in warning.getMessage()
    assert warning.endpoint == url  # type: ignore[attr-defined]


async def test_hooks_of_another_type_are_refused_before_anything_opens() -> None:
    with pytest.raises(aiofins.CommandError, match=r"hooks must be an aiofins\.EventHooks; got"):
        async with aiofins.connect("udp://127.0.0.1:9", hooks=[print]):  # type: ignore[arg-type]
            pass
    with pytest.raises(aiofins.CommandError, match=r"hooks must be an aiofins\.EventHooks"):
        aiofins.Pool(hooks=print)
