"""The write guard (#17 item 8): a read-only client refuses every command that changes the PLC
before anything is sent; reads still work. Checked for every operation against the simulator."""

from __future__ import annotations

import contextlib

import pytest

import aiofins
from aiofins.protocol.commands import ALL_OPERATIONS
from aiofins.protocol.guard import CHANGES
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator

from .test_all_operations import SCRIPT

pytestmark = pytest.mark.anyio

#: The operations that only read (all others change the PLC).
READS = {
    "memory_area_read",
    "multiple_memory_area_read",
    "parameter_area_read",
    "program_area_read",
    "cpu_unit_data_read",
    "connection_data_read",
    "cpu_unit_status_read",
    "cycle_time_read",
    "clock_read",
    "message_read",
    "fal_fals_read",
    "error_log_read",
    "fins_write_access_log_read",
    "file_name_read",
    "single_file_read",
    "memory_cassette_transfer",  # the script reads the cassette's data type
}


def vplc(sim: Simulator) -> VirtualPLC:
    assert isinstance(sim.plc, VirtualPLC)
    return sim.plc


def test_the_table_has_every_command_code_of_the_manual() -> None:
    assert set(CHANGES) == {op.command_code() for op in ALL_OPERATIONS}


async def test_every_operation_is_guarded(url: str, sim: Simulator) -> None:
    plc_state = vplc(sim)
    plc_state.write("D0", [7, 8])
    async with aiofins.connect(url, read_only=True, retries=0) as plc:
        assert plc.read_only
        for name, step in SCRIPT:
            before = plc_state.frames_handled
            if name in READS:
                with contextlib.suppress(aiofins.EndCodeError):  # answered: it was sent
                    await step(plc)
                assert plc_state.frames_handled == before + 1, name
                continue
            with pytest.raises(aiofins.ReadOnlyError, match="read-only client") as info:
                await step(plc)
            assert plc_state.frames_handled == before, f"{name} reached the PLC"
            assert info.value.changes == CHANGES[info.value.command_code]
        assert await plc.read("D0", 2) == [7, 8]
    assert plc_state.read("D0", 2) == [7, 8]
    assert plc_state.mode.name == "PROGRAM"  # neither run nor stop got through
    assert plc_state.write_log == []


async def test_helpers_raw_frames_and_tags_are_guarded(url: str, sim: Simulator) -> None:
    plc_state = vplc(sim)
    async with aiofins.connect(url + "?read_only=1") as plc:
        before = plc_state.frames_handled
        refused = [
            plc.write("D0", [1]),
            plc.write_value("D0", 1.5, "float32"),
            plc.write("D0", [1] * 2000, allow_split=True),  # several frames: none is sent
            plc.execute(0x01, 0x02, b"\x82\x00\x00\x00\x00\x01\x00\x01"),
            plc.execute(0x09, 0x20, b"\x40\xff"),  # MESSAGE CLEAR
            plc.execute(0x06, 0x20, b"\x00"),  # CYCLE TIME READ that initializes
            plc.execute(0x22, 0x20, b"\x00\x00\x00\x01\x00\x00"),  # cassette → CPU unit
            plc.execute(0x7F, 0x7F, b""),  # unknown: may change anything
            plc.execute_many([(0x01, 0x01, b"\x82\x00\x00\x00\x00\x01"), (0x04, 0x02, b"")]),
        ]
        for coro in refused:
            with pytest.raises(aiofins.ReadOnlyError):
                await coro
        assert plc_state.frames_handled == before
        assert await plc.read_tags({"a": "D0", "b": "D100:float32"}) == {"a": 0, "b": 0.0}
        await plc.execute(0x09, 0x20, b"\x00\xff")  # MESSAGE READ goes through
        with pytest.raises(aiofins.EndCodeError):  # sent: a CJ2 has no cassette (0401)
            await plc.execute(0x22, 0x20, b"\x00\x00\x80\x00")  # cassette data type
    assert plc_state.read("D0") == [0]


async def test_pool_read_only_and_per_borrower_urls(url: str, sim: Simulator) -> None:
    plc_state = vplc(sim)
    async with aiofins.connect(url + "?read_only") as plc:  # bare: on, never ignored
        assert plc.read_only
    async with aiofins.connect(url + "?read_only=0") as plc:
        assert not plc.read_only
    async with aiofins.Pool(read_only=True) as pool, pool.client(url) as plc:
        with pytest.raises(aiofins.ReadOnlyError):
            await plc.write("D0", [1])
        assert await plc.read("D0") == [0]
    async with aiofins.Pool() as pool:
        async with pool.client(url + "?read_only=yes") as guarded:
            with pytest.raises(aiofins.ReadOnlyError):
                await guarded.stop()
        async with pool.client(url) as plc:  # the same session, its borrower's own guard
            assert not plc.read_only and plc.session is guarded.session
            await plc.write("D0", [5])
        async with pool.client(url + "?read_only=1") as again:
            assert again is guarded
            with pytest.raises(aiofins.ReadOnlyError):
                await again.write("D0", [6])
    assert plc_state.read("D0") == [5]


async def test_bulk_restore_and_upload_are_guarded(url: str, sim: Simulator) -> None:
    from aiofins.bulk import restore_parameters, restore_program, upload_file
    from aiofins.protocol.commands.parameter import PARAMETER_AREA_WORDS
    from aiofins.protocol.files import Disk

    plc_state = vplc(sim)
    async with aiofins.connect(url, read_only=True) as plc:
        before = plc_state.frames_handled
        with pytest.raises(aiofins.ReadOnlyError):
            await upload_file(plc, Disk.MEMORY_CARD, "A.TXT", b"hello")
        with pytest.raises(aiofins.ReadOnlyError):
            await restore_parameters(plc, {0x8010: (0,) * PARAMETER_AREA_WORDS[0x8010]})
        with pytest.raises(aiofins.ReadOnlyError):
            await restore_program(plc, b"\x00" * 8)
        assert plc_state.frames_handled == before


def test_read_only_error_is_a_command_error() -> None:
    assert issubclass(aiofins.ReadOnlyError, aiofins.CommandError)
    assert issubclass(aiofins.ReadOnlyError, aiofins.FinsError)
