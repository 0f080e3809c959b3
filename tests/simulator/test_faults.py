"""Fault injection: each fault seen on the wire as configured, and reproducible by seed."""

from __future__ import annotations

import io
import logging
import math
import pathlib
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import pytest
from anyio.abc import UDPSocket
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.errors import FrameError
from aiofins.protocol.hostlink import decode_response
from aiofins.simulator import (
    Delay,
    FaultDecision,
    FaultPlan,
    FaultRule,
    FrameLog,
    Simulator,
    run_simulator,
)

from ..virtual_time import on_virtual_time
from .test_servers import (
    READ_D100,
    READ_D100_REPLY,
    handshake,
    make_plc,
    node_response,
    with_sid,
)

# CPU UNIT STATUS READ, SID EE, never faulted: its answer marks the end of a sequence.
MARKER = bytes.fromhex("80 00 02 00 0A 00 00 22 00 EE 06 01")
MARKER_REPLY_HEAD = bytes.fromhex("C0 00 02 00 22 00 00 0A 00 EE 06 01 00 00")
CLEAN = {0x0601: FaultRule()}


@asynccontextmanager
async def udp_sim(plan: FaultPlan) -> AsyncIterator[tuple[Simulator, UDPSocket]]:
    async with (
        run_simulator(make_plc(), udp=("127.0.0.1", 0), faults=plan) as sim,
        await anyio.create_udp_socket(local_host="127.0.0.1") as sock,
    ):
        yield sim, sock


async def send(sim: Simulator, sock: UDPSocket, frame: bytes) -> None:
    await sock.sendto(frame, "127.0.0.1", sim.udp_port)


async def recv(sock: UDPSocket, timeout: float = 5) -> bytes:
    with anyio.fail_after(timeout):
        data, _ = await sock.receive()
    return data


async def recv_until_marker(sock: UDPSocket) -> list[bytes]:
    out: list[bytes] = []
    while not (data := await recv(sock)).startswith(MARKER_REPLY_HEAD):
        out.append(data)
    return out


def plan_for_read(rule: FaultRule) -> FaultPlan:
    """Faults on 0101 only; 0601 (the marker) always clean."""
    return FaultPlan(per_command={0x0101: rule, **CLEAN}, seed=7)


# ---- on the wire ----------------------------------------------------------------------------


@pytest.mark.anyio
async def test_drop_request() -> None:
    async with udp_sim(plan_for_read(FaultRule(drop_request=1.0))) as (sim, sock):
        await send(sim, sock, READ_D100)
        await send(sim, sock, MARKER)
        assert await recv_until_marker(sock) == []
        assert sim.counters.dropped_requests == 1
        assert sim.counters.requests == 2
        assert sim.counters.responses == 1


@pytest.mark.anyio
async def test_drop_response() -> None:
    async with udp_sim(plan_for_read(FaultRule(drop_response=1.0))) as (sim, sock):
        await send(sim, sock, READ_D100)
        await send(sim, sock, MARKER)
        assert await recv_until_marker(sock) == []
        assert sim.counters.dropped_responses == 1
        assert sim.counters.dropped_requests == 0


@pytest.mark.anyio
async def test_duplicate() -> None:
    async with udp_sim(plan_for_read(FaultRule(duplicate=1.0))) as (sim, sock):
        await send(sim, sock, READ_D100)
        await send(sim, sock, MARKER)
        assert await recv_until_marker(sock) == [READ_D100_REPLY, READ_D100_REPLY]
        assert sim.counters.duplicated == 1


@pytest.mark.anyio
async def test_reorder_holds_until_next_response() -> None:
    async with udp_sim(plan_for_read(FaultRule(reorder=1.0))) as (sim, sock):
        await send(sim, sock, READ_D100)
        await send(sim, sock, MARKER)
        assert (await recv(sock)).startswith(MARKER_REPLY_HEAD)
        assert await recv(sock) == READ_D100_REPLY
        assert sim.counters.reordered == 1


@on_virtual_time
async def test_delay_does_not_hold_up_later_requests() -> None:
    # On virtual time (asyncio, trio; uvloop's clock cannot be virtual): the marker overtakes
    # the read whatever the machine's load, and the delay is exact.
    rule = FaultRule(delay=Delay(1.0, 1.0))
    async with udp_sim(plan_for_read(rule)) as (sim, sock):
        start = anyio.current_time()
        await send(sim, sock, READ_D100)
        await send(sim, sock, MARKER)
        assert (await recv(sock)).startswith(MARKER_REPLY_HEAD)
        assert await recv(sock) == READ_D100_REPLY
        assert anyio.current_time() - start == pytest.approx(1.0, abs=1e-6)
        assert sim.counters.delayed == 1


@on_virtual_time
async def test_late_answer() -> None:
    rule = FaultRule(late=1.0, late_after=0.3, delay=Delay(0.0, 0.01))
    async with udp_sim(plan_for_read(rule)) as (sim, sock):
        start = anyio.current_time()
        await send(sim, sock, READ_D100)
        assert await recv(sock) == READ_D100_REPLY
        assert anyio.current_time() - start == pytest.approx(0.3, abs=1e-6)
        assert sim.counters.late == 1
        assert sim.counters.delayed == 0


@pytest.mark.anyio
async def test_corrupt_changes_exactly_one_byte() -> None:
    async with udp_sim(plan_for_read(FaultRule(corrupt=1.0))) as (sim, sock):
        await send(sim, sock, READ_D100)
        reply = await recv(sock)
    assert len(reply) == len(READ_D100_REPLY)
    assert sum(a != b for a, b in zip(reply, READ_D100_REPLY, strict=True)) == 1
    assert sim.counters.corrupted == 1


@pytest.mark.anyio
async def test_truncate_sends_a_prefix() -> None:
    async with udp_sim(plan_for_read(FaultRule(truncate=1.0))) as (sim, sock):
        await send(sim, sock, READ_D100)
        reply = await recv(sock)
    assert 1 <= len(reply) < len(READ_D100_REPLY)
    assert READ_D100_REPLY.startswith(reply)
    assert sim.counters.truncated == 1


@pytest.mark.anyio
@pytest.mark.parametrize(
    ("rule", "tail"),
    [
        (FaultRule(end_code=0x1103), "11 03"),
        (FaultRule(end_code=0x8205, relay=(1, 5)), "82 05 01 05"),
        (FaultRule(flags=0x40), "00 40" + READ_D100_REPLY[14:].hex()),
        (FaultRule(flags=0x80, end_code=0x2203), "22 83"),
    ],
)
async def test_end_code_relay_and_flags(rule: FaultRule, tail: str) -> None:
    async with udp_sim(plan_for_read(rule)) as (sim, sock):
        await send(sim, sock, READ_D100)
        reply = await recv(sock)
    assert reply == READ_D100_REPLY[:12] + bytes.fromhex(tail)


@pytest.mark.anyio
async def test_max_concurrent_answers_2604() -> None:
    # The delay keeps the first two in flight while the third arrives, even on a loaded machine.
    plan = FaultPlan(FaultRule(delay=Delay(1.0, 1.0)), per_command=CLEAN, max_concurrent=2)
    async with udp_sim(plan) as (sim, sock):
        for sid in (1, 2, 3):
            await send(sim, sock, with_sid(READ_D100, sid))
        busy = await recv(sock)
        assert busy == with_sid(READ_D100_REPLY[:12], 3) + b"\x26\x04"
        assert sorted([await recv(sock), await recv(sock)]) == [
            with_sid(READ_D100_REPLY, 1),
            with_sid(READ_D100_REPLY, 2),
        ]
        assert sim.counters.busy == 1
        assert sim.dispatcher.in_flight == 0


@pytest.mark.anyio
async def test_tcp_refusal() -> None:
    plan = FaultPlan(tcp_refusal=0x25)
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), faults=plan) as sim:
        peer, reply = await handshake(sim.tcp_port)
        async with peer.stream:
            assert reply == node_response(0, 10, 0x25)
            assert await peer.closed_by_server()
        assert sim.counters.tcp_refusals == 1


@pytest.mark.anyio
async def test_tcp_corrupt_keeps_envelope_valid() -> None:
    plan = FaultPlan(FaultRule(truncate=1.0), seed=3)
    async with run_simulator(make_plc(), tcp=("127.0.0.1", 0), faults=plan) as sim:
        peer, _ = await handshake(sim.tcp_port)
        async with peer.stream:
            await peer.stream.send(
                b"FINS"
                + (8 + 18).to_bytes(4, "big")
                + bytes.fromhex("00000002 00000000")
                + READ_D100
            )
            message = await peer.read_message()
    length = int.from_bytes(message[4:8], "big")
    assert length == len(message) - 8 < 8 + len(READ_D100_REPLY)
    assert message[8:16] == bytes.fromhex("00000002 00000000")


class BrokenPLC:
    def handle_frame(self, frame: bytes, *, from_network: bool = True) -> bytes | None:
        if frame[10] == 0x01:
            raise RuntimeError("bug")
        return make_plc().handle_frame(frame, from_network=from_network)


@pytest.mark.anyio
async def test_plc_exception_is_counted_not_fatal() -> None:
    async with (
        run_simulator(BrokenPLC(), udp=("127.0.0.1", 0)) as sim,
        await anyio.create_udp_socket(local_host="127.0.0.1") as sock,
    ):
        await send(sim, sock, READ_D100)
        await send(sim, sock, MARKER)
        assert await recv_until_marker(sock) == []
        assert sim.counters.handler_errors == 1


# ---- reproducible by seed -------------------------------------------------------------------

MIXED = FaultRule(drop_request=0.2, drop_response=0.2, duplicate=0.3, corrupt=0.3, truncate=0.2)


async def run_mixed(seed: int) -> tuple[list[bytes], dict[str, int]]:
    async with udp_sim(FaultPlan(MIXED, per_command=CLEAN, seed=seed)) as (sim, sock):
        for sid in range(40):
            await send(sim, sock, with_sid(READ_D100, sid))
        await send(sim, sock, MARKER)
        return await recv_until_marker(sock), sim.counters.as_dict()


@pytest.mark.anyio
async def test_same_seed_same_wire_bytes() -> None:
    first, counters = await run_mixed(42)
    again, counters_again = await run_mixed(42)
    other, _ = await run_mixed(43)
    assert first == again
    assert counters == counters_again
    assert first != other
    assert counters["corrupted"] > 0
    assert counters["dropped_requests"] > 0


def test_decisions_are_aligned_whatever_the_rule() -> None:
    frames = [with_sid(READ_D100, i) for i in range(200)]
    only_drop = FaultPlan(FaultRule(drop_request=0.5), seed=9)
    everything = FaultPlan(FaultRule(drop_request=0.5, duplicate=0.5, corrupt=1.0), seed=9)
    a = [only_drop.decide(f).drop_request for f in frames]
    b = [everything.decide(f).drop_request for f in frames]
    assert a == b
    assert 50 < sum(a) < 150


def test_per_command_rule() -> None:
    plan = FaultPlan(FaultRule(), per_command={0x0101: FaultRule(end_code=0x1101)}, seed=0)
    assert plan.decide(READ_D100).end_code == 0x1101
    assert plan.decide(MARKER).end_code is None
    assert plan.decide(b"\x80").end_code is None  # too short to have a command code


# ---- the pure parts -------------------------------------------------------------------------


@given(st.binary(min_size=0, max_size=64), st.floats(0, 0.999), st.integers(1, 255))
def test_damage_binary(wire: bytes, position: float, mask: int) -> None:
    plan = FaultPlan()
    corrupted = plan.damage(wire, FaultDecision(corrupt=(position, mask)))
    assert len(corrupted) == len(wire)
    assert sum(a != b for a, b in zip(corrupted, wire, strict=True)) == (1 if wire else 0)
    truncated = plan.damage(wire, FaultDecision(truncate=position))
    assert wire.startswith(truncated)
    assert len(truncated) < len(wire) or len(wire) <= 1


HOSTLINK_REPLY = b"@00FA004000000001010000000100020003000400050006000700080009000A33*\r"


@given(st.floats(0, 0.999), st.integers(1, 255), st.booleans())
def test_damage_hostlink_line(position: float, mask: int, truncate: bool) -> None:
    plan = FaultPlan()
    decision = (
        FaultDecision(truncate=position) if truncate else FaultDecision(corrupt=(position, mask))
    )
    line = plan.damage(HOSTLINK_REPLY, decision, hostlink=True)
    assert line.startswith(b"@")
    assert line.endswith(b"*\r")
    assert line != HOSTLINK_REPLY
    with pytest.raises(FrameError):
        decode_response(line, full_header=False)


def test_rewrite_ignores_short_frames() -> None:
    plan = FaultPlan()
    assert plan.rewrite(b"\xc0\x00", FaultDecision(end_code=0x1001, flags=0x40)) == b"\xc0\x00"


def test_delay_parse_and_rule_validation() -> None:
    assert Delay.parse_ms("50") == Delay(0.05, 0.05)
    assert Delay.parse_ms("10-200") == Delay(0.01, 0.2)
    for bad in ("x", "5-1", "-3"):
        with pytest.raises(ValueError):
            Delay.parse_ms(bad)
    for kwargs in ({"drop_request": 1.5}, {"flags": 0x01}, {"end_code": 0x10000}):
        with pytest.raises(ValueError):
            FaultRule(**kwargs)
    with pytest.raises(ValueError):
        FaultPlan(max_concurrent=0)


@pytest.mark.anyio
async def test_frame_log_to_stream_and_logger(caplog: pytest.LogCaptureFixture) -> None:
    stream = io.StringIO()
    async with udp_sim(FaultPlan(log=FrameLog(stream))) as (sim, sock):
        await send(sim, sock, READ_D100)
        await recv(sock)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2
    assert lines[0].split(" ", 3)[1] == "rx" and lines[0].endswith(READ_D100.hex(" "))
    assert lines[1].split(" ", 3)[1] == "tx" and lines[1].endswith(READ_D100_REPLY.hex(" "))

    logger = logging.getLogger("test.frames")
    with caplog.at_level(logging.INFO, logger="test.frames"):
        async with udp_sim(FaultPlan(log=FrameLog(logger))) as (sim, sock):
            await send(sim, sock, READ_D100)
            await recv(sock)
    messages = [r.getMessage() for r in caplog.records if r.name == "test.frames"]
    assert messages[0].startswith("rx udp:127.0.0.1:")
    assert messages[1].endswith(READ_D100_REPLY.hex(" "))


@given(
    st.binary(max_size=40),
    st.one_of(st.none(), st.integers(0, 0xFFFF)),
    st.sampled_from([0, 0x40, 0x80, 0xC0]),
)
def test_rewrite_keeps_header_and_sets_end_code(
    response: bytes, end_code: int | None, flags: int
) -> None:
    out = FaultPlan().rewrite(response, FaultDecision(end_code=end_code, relay=(1, 2), flags=flags))
    if len(response) < 14:
        assert out == response
        return
    assert out[:12] == response[:12]
    ec = int.from_bytes(out[12:14], "big")
    if end_code is None:
        assert ec == int.from_bytes(response[12:14], "big") | flags
        assert out[14:] == response[14:]
    else:
        assert ec == end_code | flags
        assert out[14:] == (b"\x01\x02" if end_code & 0x8000 else b"")


@pytest.mark.anyio
async def test_frame_log_to_file_and_urls(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "frames.log"
    log = FrameLog(path)
    async with udp_sim(FaultPlan(log=log)) as (sim, sock):
        assert sim.urls() == [f"udp://127.0.0.1:{sim.udp_port}"]
        await send(sim, sock, READ_D100)
        await recv(sock)
    log.close()
    words = [line.split(" ") for line in path.read_text().splitlines()]
    assert [w[1] for w in words] == ["rx", "tx"]
    assert bytes.fromhex("".join(words[0][3:])) == READ_D100


@on_virtual_time
async def test_held_answers_are_bounded_the_rest_dropped_and_counted() -> None:
    """--delay/--late held one task per delayed request without bound (61k requests: RSS
    31 -> 388 MB). At most max_held wait; the rest are dropped and counted. On virtual time:
    the 1 s delay holds the first ones while the others arrive, whatever the load."""
    plan = plan_for_read(FaultRule(delay=Delay(1.0, 1.0)))  # held while the other eight arrive
    plan.max_held = 3
    async with udp_sim(plan) as (sim, sock):
        for sid in range(10):
            await send(sim, sock, with_sid(READ_D100, sid))
        await send(sim, sock, MARKER)  # answered at once, after the ten were dispatched
        assert (await recv(sock)).startswith(MARKER_REPLY_HEAD)
        assert sim.counters.held_dropped == 7
        assert sim.dispatcher.waiting == 3
        replies = [await recv(sock) for _ in range(3)]
        assert sorted(r[9] for r in replies) == [0, 1, 2]
        assert all(with_sid(r, 1) == with_sid(READ_D100_REPLY, 1) for r in replies)
        assert sim.counters.delayed == 3
        with anyio.fail_after(5):
            while sim.dispatcher.waiting:  # the tasks end right after their answer
                await anyio.sleep(0.001)
        await send(sim, sock, with_sid(READ_D100, 42))  # room again
        assert await recv(sock) == with_sid(READ_D100_REPLY, 42)
        assert sim.counters.held_dropped == 7


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_held": math.nan}, "max_held must be a whole number, at least 1"),
        ({"max_held": 2.5}, "max_held must be a whole number"),
        ({"max_held": True}, "max_held must be a whole number"),
        ({"max_concurrent": math.nan}, "max_concurrent must be a whole number"),
        ({"max_concurrent": 0}, "max_concurrent must be a whole number"),
    ],
)
def test_a_plan_refuses_bounds_that_bound_nothing(kwargs: dict[str, Any], message: str) -> None:
    """``max_held=nan`` passed the ``< 1`` check, and every ``waiting >= nan`` was false: the
    held answers were unbounded again."""
    with pytest.raises(ValueError, match=message):
        FaultPlan(**kwargs)
