"""The client over Host Link FINS to the virtual PLC's serial server, through a socat pty pair."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from aiofins.connection import connect
from aiofins.protocol.commands.status import CpuMode
from aiofins.protocol.errors import ConnectionLost, EndCodeError, FinsTimeout
from aiofins.simulator.faults import FaultPlan, FaultRule
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator
from tests.client.test_all_operations import EXPECTED_END_CODES, run_script
from tests.conftest import PTY_8N1, PTY_LINE

pytestmark = [
    pytest.mark.anyio,
    pytest.mark.serial,
    pytest.mark.skipif(shutil.which("socat") is None, reason="socat is not installed"),
]


async def test_read_write_status_and_host_link_chunking(pty_pair: tuple[str, str]) -> None:
    plc_side, host_side = pty_pair
    plc = VirtualPLC()
    url = f"serial://{host_side}?baudrate=115200&unit=0&{PTY_8N1}"
    async with (
        run_simulator(plc, serial=plc_side, serial_settings=PTY_LINE) as sim,
        # retries=0: every frame goes out once, however loaded the machine (counted below)
        connect(url, timeout=2, retries=0) as client,
    ):
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
    url = f"serial://{host_side}?baudrate=115200&{PTY_8N1}"
    async with run_simulator(
        VirtualPLC(), serial=plc_side, serial_settings=PTY_LINE, faults=plan
    ) as sim:
        # A call's whole budget is generous (a loaded machine's pty is slow); what a
        # corrupted reply costs is a retransmission after the RTO, not this timeout.
        async with connect(url, timeout=5, retries=5) as client:
            await client.write("D0", list(range(20)), retries=5)
            got = [(await client.read(f"D{i}"))[0] for i in range(20)]
            assert got == list(range(20))
            assert client.session.stats.malformed > 0
        assert sim.counters.corrupted > 0


async def test_every_operation_is_answered_over_host_link(pty_pair: tuple[str, str]) -> None:
    plc_side, host_side = pty_pair
    url = f"serial://{host_side}?baudrate=115200&{PTY_8N1}"
    async with (
        run_simulator(VirtualPLC(), serial=plc_side, serial_settings=PTY_LINE),
        connect(url, timeout=2) as client,
    ):
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
    async with run_simulator(
        plc, serial=plc_side, serial_settings=PTY_LINE, udp=("127.0.0.1", 0)
    ) as sim:
        async with connect(f"serial://{host_side}?baudrate=115200&{PTY_8N1}", timeout=2) as client:
            await client.write("D10", [42])  # Host Link is not a network: allowed
            assert await client.read("D10") == [42]
        async with connect(f"udp://127.0.0.1:{sim.udp_port}", timeout=2) as client:
            with pytest.raises(EndCodeError) as info:
                await client.write("D10", [1])  # over the network: refused
            assert info.value.end_code.code == 0x2102
            assert await client.read("D10") == [42]


async def test_a_silent_line_gets_serial_advice_not_the_network_checklist(
    pty_pair: tuple[str, str],
) -> None:
    """Nobody answers on the line: the timeout names what to check on a serial line (the
    settings, Host Link mode, the unit number, the wiring), not FINS nodes and ports."""
    _, host_side = pty_pair
    async with connect(f"serial://{host_side}?unit=3&{PTY_8N1}", timeout=0.2) as client:
        with pytest.raises(FinsTimeout) as info:
            await client.read("D0")
    message = str(info.value)
    for words in (
        "line settings match the PLC's serial port (here 9600 8N1",
        "factory setting is 9600 7E2",
        "Host Link (SYSWAY) mode",
        "unit=3 here",
        "wiring (TX and RX crossed",
    ):
        assert words in message, message
    assert "SA1" not in message and "DA1" not in message


@pytest.mark.parametrize("anyio_backend", ["asyncio"])
async def test_the_7e2_default_on_a_pty_says_what_a_pty_takes(
    pty_pair: tuple[str, str], anyio_backend: str
) -> None:
    """serial_asyncio_fast sets the line again after opening it, and Linux refuses 7E2 on a
    pty (pyserial alone, under trio, leaves it be)."""
    _, host_side = pty_pair
    with pytest.raises(ConnectionLost) as info:
        async with connect(f"serial://{host_side}", timeout=0.5) as client:
            await client.read("D0")
    assert "refused the line settings 9600 7E2" in str(info.value)
    assert "?bytesize=8&parity=N&stopbits=1" in str(info.value)


async def test_a_missing_device_asks_whether_the_adapter_is_plugged_in(tmp_path: Path) -> None:
    device = tmp_path / "ttyUSB9"
    with pytest.raises(ConnectionLost) as info:
        async with connect(f"serial://{device}", timeout=0.5) as client:
            await client.read("D0")
    assert f"there is no {device}: is the adapter plugged in?" in str(info.value)


PERMISSION_SCRIPT = """
import anyio, aiofins
async def main():
    async with aiofins.connect("serial://{device}", timeout=0.5) as plc:
        await plc.read("D0")
try:
    anyio.run(main, backend={backend!r})
except aiofins.ConnectionLost as exc:
    print(exc)
"""


@pytest.mark.skipif(
    shutil.which("setpriv") is None or os.geteuid() != 0,
    reason="needs root and setpriv to open a device without the right to",
)
@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_permission_denied_names_the_dialout_group(tmp_path: Path, backend: str) -> None:
    """A device this process may not open, as a user outside 'dialout' meets /dev/ttyUSB0:
    owned by another user, mode 600, opened without the capability to override that."""
    device = tmp_path / "ttyUSB0"
    device.touch(mode=0o600)
    os.chown(device, 65534, 65534)
    no_override = "-dac_override,-dac_read_search"
    result = subprocess.run(
        [
            "setpriv",
            f"--inh-caps={no_override}",
            f"--bounding-set={no_override}",
            sys.executable,
            "-c",
            PERMISSION_SCRIPT.format(device=device, backend=backend),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert "Permission denied" in result.stdout
    assert "add it to the 'dialout' group (sudo usermod -aG dialout $USER" in result.stdout
