"""The client against the virtual PLC over real loopback UDP and FINS/TCP (asyncio and trio)."""

from __future__ import annotations

from datetime import datetime

import anyio
import pytest

import aiofins
from aiofins.connection import connect
from aiofins.protocol.commands.errorlog import ErrorLog, ErrorLogRecord
from aiofins.protocol.commands.status import CpuMode
from aiofins.protocol.errors import (
    AddressError,
    CommandError,
    EndCodeError,
    FinsTimeout,
    WriteNotPossibleError,
)
from aiofins.protocol.header import FinsAddress
from aiofins.protocol.limits import NetworkType
from aiofins.simulator.faults import FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator

from ..session.test_session_udp import reply, udp_responder
from ..virtual_time import on_virtual_time

pytestmark = pytest.mark.anyio


async def test_words_bits_and_typed_values(url: str) -> None:
    async with connect(url, timeout=1) as plc:
        await plc.write("D100", [1, 2, 0xFFFF])
        assert await plc.read("D100", 3) == [1, 2, 0xFFFF]
        await plc.write("CIO 10.14", [1, 1, 0])
        assert await plc.read("CIO 10.14", 3) == [1, 1, 0]
        assert await plc.read("CIO 10", 2) == [0xC000, 0]  # bits 14 and 15; CIO 11.00 off
        assert await plc.read_bit("CIO 10.15") is True
        await plc.write_value("D200", -2.5, "float32")
        assert await plc.read("D200", 2) == [0x0000, 0xC020]  # CDAB: low word first
        assert await plc.read_value("D200", "float32") == -2.5
        await plc.write_values("D300", [-1, 70000], "int32")
        assert await plc.read_values("D300", "int32", 2) == [-1, 70000]
        await plc.write_value("D400", "HELLO", "string:6")
        assert await plc.read_value("D400", "string:6") == "HELLO"


async def test_read_and_write_of_count_zero(url: str) -> None:
    async with connect(url, timeout=1) as plc:
        assert await plc.read("D0", 0) == []
        await plc.write("D0", [])


async def test_full_dm_round_trip_in_expected_frames(sim: Simulator, url: str) -> None:
    data = [(i * 7) & 0xFFFF for i in range(32768)]
    async with connect(url, timeout=2) as plc:
        with pytest.raises(CommandError, match="not atomic"):
            await plc.write("D0", data)
        await plc.write("D0", data, allow_split=True)
        # Requests answered: a retransmission (a loaded machine delays a reply past the
        # retransmission timeout) reaches the simulator but answers no second request.
        before = plc.session.stats.completed
        assert await plc.read("D0", 32768) == data
        assert plc.session.stats.completed - before == 33  # ceil(32768 / 999)
    async with connect(url, timeout=2, networks=(NetworkType.SYSMAC_LINK,)) as plc:
        before = plc.session.stats.completed
        assert await plc.read("D0", 32768) == data
        assert plc.session.stats.completed - before == 122  # ceil(32768 / 269)


async def test_thousand_concurrent_reads_each_get_their_own_value(url: str) -> None:
    # A read's timeout counts its wait for a SID behind the other 999 (real sockets, real
    # time): 60 s is a hang guard, not a bound on speed (5 s ran out under trio at load 15).
    async with connect(url, timeout=60) as plc:
        await plc.write("D0", list(range(1000)), allow_split=True)
        results: dict[int, list[int]] = {}

        async def one(i: int) -> None:
            results[i] = await plc.read(f"D{i}", 1)

        async with anyio.create_task_group() as tg:
            for i in range(1000):
                tg.start_soon(one, i)
        assert results == {i: [i] for i in range(1000)}
        assert plc.session.stats.completed >= 1001


async def test_end_codes_raise_typed_errors_with_meaning(url: str) -> None:
    async with connect(url, timeout=1) as plc:
        with pytest.raises(WriteNotPossibleError) as info:
            await plc.write("A0", [1])  # A0-A447 are read-only
        assert info.value.end_code.code == 0x2101
        assert "read-only" in str(info.value).lower() or info.value.end_code.name


async def test_status_clock_mode_and_commands(url: str) -> None:
    async with connect(url, timeout=1) as plc:
        status = await plc.cpu_unit_status_read()
        assert status.mode == CpuMode.PROGRAM
        await plc.run()
        assert (await plc.cpu_unit_status_read()).mode == CpuMode.MONITOR
        await plc.stop()
        assert (await plc.cpu_unit_status_read()).mode == CpuMode.PROGRAM
        clock = await plc.clock_read()
        assert clock.time.year >= 2024


async def test_cpu_error_flags_ride_on_the_result(sim: Simulator, url: str) -> None:
    sim.plan.rule = FaultRule(flags=0x40)
    async with connect(url, timeout=1) as plc:
        assert await plc.read("D0", 1) == [0]
        assert plc.last_end_code is not None
        assert plc.last_end_code.non_fatal_cpu_error
        assert plc.last_end_code.is_normal


async def test_relay_error_names_the_failing_node(sim: Simulator, url: str) -> None:
    async with connect(url, timeout=1) as plc:
        with pytest.raises(aiofins.RelayError) as info:
            await plc.read("D0", 1, dest=FinsAddress(5, 9, 0))
        assert info.value.end_code.relay_error


@pytest.mark.parametrize("scheme", ["udp", "tcp"])
@on_virtual_time
async def test_timeout_is_raised_and_the_next_call_works(scheme: str) -> None:
    """On virtual time (asyncio, trio; uvloop's clock cannot be virtual): the 0.2 s timeout
    ends the ignored call only, never a loaded machine's slow answer to the next."""
    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0)) as sim:
        port = sim.udp_port if scheme == "udp" else sim.tcp_port
        await _timeout_is_raised_and_the_next_call_works(sim, f"{scheme}://127.0.0.1:{port}")


async def _timeout_is_raised_and_the_next_call_works(sim: Simulator, url: str) -> None:
    sim.plan.per_command[0x0601] = FaultRule(drop_request=1.0)
    async with connect(url, timeout=0.2, retries=0) as plc:
        with pytest.raises(FinsTimeout):
            await plc.cpu_unit_status_read()
        assert await plc.read("D0", 1) == [0]
        assert plc.session.stats.timeouts == 1


async def test_addressing_end_codes_say_what_to_check(sim: Simulator, url: str) -> None:
    sim.plan.per_command[0x0101] = FaultRule(end_code=0x1005)
    async with connect(url, timeout=1) as plc:
        with pytest.raises(aiofins.EndCodeError) as info:
            await plc.read("D0")
        assert info.value.end_code.code == 0x1005
        assert "Check the FINS addresses: destination 0.1.0" in str(info.value)


async def test_client_word_order_is_the_default_for_typed_values(url: str) -> None:
    async with connect(url, timeout=1, word_order="ABCD") as plc:
        await plc.write_value("D500", 0x12345678, "uint32")
        assert await plc.read("D500", 2) == [0x1234, 0x5678]
        await plc.write_value("D502", 0x12345678, "uint32:CDAB")  # the spec's order wins
        assert await plc.read("D502", 2) == [0x5678, 0x1234]
        assert await plc.read_value("D500", "uint32") == 0x12345678


async def test_udp_host_name_is_resolved_for_the_node_defaults() -> None:
    """DA1 is the last octet of the PLC's IPv4 address, also when the URL names the host.

    ``127.7`` is not a dotted quad: the resolver (not our parser) makes it 127.0.0.7. The
    virtual PLC is node 7 and ignores frames for any other node, so a DA1 left at the
    fallback (1) would time out.
    """
    async with (
        run_simulator(VirtualPLC(node=7), udp=("127.0.0.7", 0)) as sim,
        connect(f"udp://127.7:{sim.udp_port}", timeout=1, retries=0) as plc,
    ):
        assert plc.session.dest.node == 7
        await plc.write("D0", [77])
        assert await plc.read("D0") == [77]


async def test_transfers_past_the_end_of_an_area_fail_before_sending(
    sim: Simulator, url: str
) -> None:
    """The client refuses what the PLC would answer 1104 for, so nothing half-happens."""
    async with connect(url, timeout=1) as plc:
        await plc.write("D32760", [1] * 8)
        sent = sim.counters.requests
        with pytest.raises(AddressError) as info:
            await plc.read("D32000", 1000)
        assert info.value.end_code == 0x1104 and "at most 768" in str(info.value)
        with pytest.raises(AddressError):  # 1,200 words: a split write, refused whole
            await plc.write("D31600", [7] * 1200, allow_split=True)
        with pytest.raises(AddressError):
            await plc.write_value("D32767", 1.5, "float32")
        with pytest.raises(AddressError):
            await plc.read("CIO 6143.15", 2)
        assert sim.counters.requests == sent  # nothing was sent
        assert await plc.read("D31600", 2) == [0, 0]  # and nothing written
        assert await plc.read("D32760", 8) == [1] * 8  # up to the last word is fine
        assert await plc.read("A440", 16) == [0] * 16  # A0-A447 and A448-A959 are one area
        with pytest.raises(AddressError, match="tag 'x'"):
            plc.compile_tags({"x": "D32767:int32"})


async def test_per_call_destination_as_text(sim: Simulator, url: str) -> None:
    """``dest`` per call takes "NET.NODE.UNIT" as connect does (DNA/DA1/DA2 per call)."""
    async with connect(url, timeout=1) as plc:
        node = plc.dest.node
        await plc.write("D0", [42], dest=f"0.{node}.0")
        assert await plc.read("D0", dest=f"0.{node}") == [42]
        assert (await plc.cpu_unit_status_read(dest=f"0.{node}.0")).mode is not None
        with pytest.raises(CommandError, match=r"is not NET\.NODE"):
            await plc.read("D0", dest="node1")


async def test_virtual_plc_memory_by_address_text_agrees_with_fins() -> None:
    """What a test sets with VirtualPLC.write/write_value a client reads over FINS, and back."""
    plc = VirtualPLC()
    plc.write("D100", [1, 2, 0xFFFF])
    plc.write("CIO 10.14", [1, 1])
    plc.write_value("D200", -2.5, "float32")
    plc.write_value("H10", "LOT-42", "string:6")
    plc.write("A0", [7])  # read-only for FINS, not for the PLC's own program
    async with (
        run_simulator(plc, udp=("127.0.0.1", 0)) as sim,
        connect(f"udp://127.0.0.1:{sim.udp_port}", timeout=1) as client,
    ):
        assert await client.read("D100", 3) == [1, 2, 0xFFFF]
        assert await client.read("CIO 10", 1) == [0xC000]
        assert await client.read_value("D200", "float32") == -2.5
        assert await client.read_value("H10", "string:6") == "LOT-42"
        assert await client.read("A0") == [7]
        await client.write("D300", [5, 6])
        await client.write("CIO 20.03", [1, 0, 1])
        await client.write_value("D400", 123456, "int32")
        assert plc.read("D300", 2) == [5, 6]
        assert plc.read("CIO 20.03", 3) == [1, 0, 1]
        assert plc.read_value("D400", "int32") == 123456
    with pytest.raises(AddressError, match="run past the end"):
        plc.read("D32767", 2)
    # What the client refuses, the virtual PLC refuses too (no silent masking).
    for address, values, limit in (
        ("D0", [70000], "0..65535"),
        ("D0", [-1], "0..65535"),
        ("CIO 0.00", [2], "0..1"),
        ("IR0", [1 << 32], "0..4294967295"),
    ):
        with pytest.raises(CommandError, match=f"{address}: value .* out of range {limit}"):
            plc.write(address, values)
    plc.write("CIO 0.00", [True])
    assert plc.read("CIO 0.00") == [1]
    with pytest.raises(CommandError, match="count must not be negative"):
        plc.read("D0", -1)
    with pytest.raises(CommandError, match=r"node 0 out of range 1\.\.254"):
        VirtualPLC(node=0)


async def test_a_tag_plan_for_bigger_frames_is_refused_on_a_smaller_route(
    sim: Simulator, url: str
) -> None:
    tags = {"first": "D0", "last": "D500"}  # one 501-word 0101 frame on Ethernet
    # retries=0: the frame goes out once, however loaded the machine (the count below is
    # exact: no retransmission reaching the simulator after ``sent`` is taken)
    async with connect(url, timeout=1, retries=0) as ethernet:
        plan = ethernet.compile_tags(tags, max_gap=600)
        assert [run.count for run in plan.runs] == [501]
        assert await ethernet.read_tags(plan) == {"first": 0, "last": 0}
    sent = sim.counters.requests
    async with connect(url, timeout=1, networks=(NetworkType.SYSMAC_LINK,)) as sysmac:
        for _ in range(2):  # every time: the check's result is kept only for routes it fits
            with pytest.raises(
                CommandError,
                match=r"has 0101 frames of up to 501 words \(the route carries 269\): ",
            ):
                await sysmac.read_tags(plan)
        assert sim.counters.requests == sent
        assert await sysmac.read_tags(tags) == {"first": 0, "last": 0}  # compiled for 269


@pytest.mark.parametrize("end_code", [0x1103, 0x1104], ids=["1103", "1104"])
async def test_short_error_log_read_returns_the_records_that_exist(
    anyio_backend: object, end_code: int
) -> None:
    """Manual 5-3-28: fewer records than asked come back with an "address range overflow",
    which 5-3-30 numbers 1103 and the end-code table 1104: the records are kept either way;
    with no data (start past the stored records) the end code is raised."""
    records = (
        ErrorLogRecord(0x80F1, 0, datetime(2026, 11, 30, 8, 15, 2)),
        ErrorLogRecord(0x0200, 0x0001, datetime(2026, 12, 1, 9, 0, 59)),
    )
    body = ErrorLog(100, 2, records).encode()
    async with (
        udp_responder(lambda cmd: [(0.0, reply(cmd, end_code, body))]) as peer,
        connect(f"udp://127.0.0.1:{peer.port}?node=1", timeout=1) as plc,
    ):
        log = await plc.error_log_read(0, 20)
        assert log.records == records and log.stored_records == 2
        assert plc.last_end_code is not None and plc.last_end_code.code == end_code
        peer.handler = lambda cmd: [(0.0, reply(cmd, end_code))]  # past the stored ones
        with pytest.raises(EndCodeError) as info:
            await plc.error_log_read(5, 20)
        assert info.value.end_code.code == end_code


async def test_typed_values_need_word_addresses(url: str) -> None:
    """A float read at a bit address would read 2 bits as its words: refused before sending."""
    async with connect(url, timeout=1) as plc:
        await plc.write("CIO 0", [0xFFFF, 0xFFFF])
        sent = plc.session.stats.completed
        for call in (
            plc.read_value("CIO 0.01", "float32"),
            plc.read_values("CIO 0.01", "int16", 2),
            plc.write_value("CIO 0.01", 1.5, "float32"),
            plc.read_value("IR0", "int32"),  # index registers: 4-byte elements
        ):
            with pytest.raises(CommandError, match="need word addresses"):
                await call
        assert plc.session.stats.completed == sent  # nothing was sent
        assert await plc.read_values("CIO 0.01", "bit", 2) == [True, True]
        await plc.write_values("CIO 0.02", [False], "bit")
        assert await plc.read("CIO 0", 1) == [0xFFFB]
        await plc.write_value("D500", 2.5, "float32")  # words: fine
        assert await plc.read_value("D500", "float32") == 2.5


async def test_progress_of_a_multi_frame_read_and_write(sim: Simulator, url: str) -> None:
    data = [(i * 3) & 0xFFFF for i in range(5000)]
    written: list[tuple[int, int]] = []
    read: list[tuple[int, int]] = []
    async with connect(url, timeout=2) as plc:
        await plc.write("D100", data, allow_split=True, progress=lambda *a: written.append(a))
        assert written == [(997 * k, 5000) for k in range(1, 6)] + [(5000, 5000)]
        # Requests answered, not frames the simulator got: on a loaded machine a reply late
        # past the retransmission timeout makes one frame arrive twice (answered once).
        before = plc.session.stats.completed
        words = await plc.read("D100", 5000, progress=lambda *a: read.append(a))
        assert words == data
        assert plc.session.stats.completed - before == 6  # ceil(5000 / 999), as without
        dones = [done for done, _ in read]
        assert dones == sorted(set(dones)) and dones[-1] == 5000
        assert all(done % 999 in (0, 5) for done in dones)  # whole frames, as they come
        # Once per frame: the steps are the frames' sizes (five of 999 words, one of 5).
        steps = [b - a for a, b in zip([0, *dones], dones, strict=False)]
        assert sorted(steps) == [5] + [999] * 5
        assert {total for _, total in read} == {5000}
        one: list[tuple[int, int]] = []
        assert await plc.read("D100", 3, progress=lambda *a: one.append(a)) == data[:3]
        assert one == [(3, 3)]


async def test_an_error_in_a_reported_read_is_raised_as_itself(sim: Simulator, url: str) -> None:
    calls: list[int] = []

    def progress(done: int, total: int) -> None:
        calls.append(done)
        if len(calls) == 2:
            raise RuntimeError("stop here")

    async with connect(url, timeout=2) as plc:
        with pytest.raises(RuntimeError, match="stop here"):
            await plc.read("D0", 9000, progress=progress)
        assert len(calls) == 2
        assert plc.session.stats.in_flight == 0  # the rest of the read abandoned
        assert await plc.read("D0", 2000) == [0] * 2000  # the client still works
        sim.plan.per_command[0x0101] = FaultRule(end_code=0x1103)
        with pytest.raises(EndCodeError) as info:
            await plc.read("D0", 3000, progress=progress, retries=0)
        assert info.value.end_code.code == 0x1103


async def test_a_reported_read_cancelled_from_its_callback_leaves_nothing_behind(
    sim: Simulator, url: str
) -> None:
    data = [(7 * i) & 0xFFFF for i in range(6000)]
    calls: list[int] = []
    async with connect(url, timeout=2) as plc:
        await plc.write("D0", data, allow_split=True)
        with anyio.CancelScope() as scope:

            def progress(done: int, total: int) -> None:
                calls.append(done)
                scope.cancel()  # from the receive path under asyncio, a task under trio

            await plc.read("D0", 6000, progress=progress)
        assert scope.cancelled_caught
        if plc.session.on_asyncio:  # the batch ends at once: nothing reported after the cancel
            assert len(calls) == 1
        else:  # a worker task already resumed with its reply may still report it
            assert 1 <= len(calls) < 7
        assert plc.session.stats.in_flight == 0
        assert all(s.slots.in_flight == 0 for s in plc.session._dests.values())
        reported: list[int] = []
        words = await plc.read("D0", 6000, progress=lambda done, _: reported.append(done))
        assert words == data
        assert len(reported) == 7 and reported[-1] == 6000
