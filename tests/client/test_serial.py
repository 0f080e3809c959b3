"""The client over Host Link FINS to the virtual PLC's serial server, through a socat pty pair."""

from __future__ import annotations

import shutil

import pytest

from aiofins.connection import connect
from aiofins.protocol.commands.status import CpuMode
from aiofins.protocol.errors import EndCodeError
from aiofins.simulator.faults import FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator
from tests.client.test_all_operations import EXPECTED_END_CODES, run_script

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.serial,
    pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed"),
]


async def test_read_write_status_and_host_link_chunking(pty_pair: tuple[str, str]) -> None:
    plc_side, host_side = pty_pair
    plc = VirtualPLC()
    url = f"serial://{host_side}?baudrate=115200&unit=0"
    async with run_simulator(plc, serial=plc_side) as sim, connect(url, timeout=2) as client:
        await client.write("D100", [7, 8, 9])
        assert await client.read("D100", 3) == [7, 8, 9]
        assert (await client.cpu_unit_status_read()).mode is CpuMode.PROGRAM
        data = [(i * 5) & 0xFFFF for i in range(600)]
        await client.write("D1000", data, allow_split=True)
        before = sim.counters.requests
        assert await client.read("D1000", 600) == data
        assert sim.counters.requests - before == 3  # Host Link: 269 words a frame
        await client.write_value("D2000", 3.25, "float64")
        assert await client.read_value("D2000", "float64") == 3.25


async def test_corrupted_lines_are_caught_by_the_fcs(pty_pair: tuple[str, str]) -> None:
    plc_side, host_side = pty_pair
    plan = FaultPlan(FaultRule(corrupt=0.3), seed=7)
    url = f"serial://{host_side}?baudrate=115200"
    async with run_simulator(VirtualPLC(), serial=plc_side, faults=plan) as sim:
        async with connect(url, timeout=0.3, retries=5) as client:
            await client.write("D0", list(range(20)), retries=5)
            got = [(await client.read(f"D{i}"))[0] for i in range(20)]
            assert got == list(range(20))
            assert client.session.stats.malformed > 0
        assert sim.counters.corrupted > 0


async def test_every_operation_is_answered_over_host_link(pty_pair: tuple[str, str]) -> None:
    plc_side, host_side = pty_pair
    url = f"serial://{host_side}?baudrate=115200"
    async with run_simulator(VirtualPLC(), serial=plc_side), connect(url, timeout=2) as client:
        outcomes = await run_script(client)
    failures = {
        name: out
        for name, out in outcomes.items()
        if isinstance(out, EndCodeError) and EXPECTED_END_CODES.get(name) != out.end_code.code
    }
    assert failures == {}
    assert len(outcomes) == 47


async def test_network_write_protection_spares_the_cpus_own_serial_port(
    pty_pair: tuple[str, str],
) -> None:
    plc_side, host_side = pty_pair
    plc = VirtualPLC(network_write_protection=True)
    async with run_simulator(plc, serial=plc_side, udp=("127.0.0.1", 0)) as sim:
        async with connect(f"serial://{host_side}?baudrate=115200", timeout=2) as client:
            await client.write("D10", [42])  # Host Link is not a network: allowed
            assert await client.read("D10") == [42]
        async with connect(f"udp://127.0.0.1:{sim.udp_port}", timeout=2) as client:
            with pytest.raises(EndCodeError) as info:
                await client.write("D10", [1])  # over the network: refused
            assert info.value.end_code.code == 0x2102
            assert await client.read("D10") == [42]
