"""Every manual-named method takes what a user types (#15): address text, lists of ints, enum
members by name, ISO times. The same script as test_all_operations.py, with text arguments."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from datetime import datetime
from typing import Any

import pytest

import aiofins
from aiofins.client import Client
from aiofins.protocol.addresses import parse_address
from aiofins.protocol.commands import ALL_OPERATIONS
from aiofins.protocol.commands.gateway import (
    ConvertToCompowayFCommand,
    ConvertToModbusAsciiCommand,
    ConvertToModbusRtuCommand,
)
from aiofins.protocol.files import Disk
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator

from .test_all_operations import EXPECTED_END_CODES

pytestmark = pytest.mark.anyio

Step = tuple[str, Callable[[Client], Awaitable[Any]]]

TEXT_SCRIPT: list[Step] = [
    ("memory_area_write", lambda p: p.memory_area_write("D0", [7, 8])),
    ("memory_area_read", lambda p: p.memory_area_read("D0", 2)),
    ("memory_area_fill", lambda p: p.memory_area_fill("D200", 50, 7)),
    ("multiple_memory_area_read", lambda p: p.multiple_memory_area_read(["D0", "D5", "CIO 1.02"])),
    ("memory_area_transfer", lambda p: p.memory_area_transfer("D200", "D300", 5)),
    ("parameter_area_read", lambda p: p.parameter_area_read("plc_setup", 0, 10)),
    ("parameter_area_write", lambda p: p.parameter_area_write("PLC_SETUP", 0, list(range(10)))),
    ("parameter_area_clear", lambda p: p.parameter_area_clear("routing_tables")),
    ("program_area_write", lambda p: p.program_area_write(0, [1, 2, 3, 4] * 2)),
    ("program_area_read", lambda p: p.program_area_read(0, 8)),
    ("program_area_clear", lambda p: p.program_area_clear("without_interrupt_tasks")),
    ("cpu_unit_data_read", lambda p: p.cpu_unit_data_read()),
    ("connection_data_read", lambda p: p.connection_data_read()),
    ("cpu_unit_status_read", lambda p: p.cpu_unit_status_read()),
    ("clock_write", lambda p: p.clock_write("2026-01-02T03:04:05")),
    ("clock_read", lambda p: p.clock_read()),
    ("message_read", lambda p: p.message_read()),
    ("message_clear", lambda p: p.message_clear(0xFF)),
    ("fal_fals_read", lambda p: p.fal_fals_read(1)),
    ("access_right_acquire", lambda p: p.access_right_acquire()),
    ("access_right_forced_acquire", lambda p: p.access_right_forced_acquire()),
    ("access_right_release", lambda p: p.access_right_release()),
    ("error_clear", lambda p: p.error_clear()),
    ("error_log_read", lambda p: p.error_log_read()),
    ("error_log_clear", lambda p: p.error_log_clear()),
    ("fins_write_access_log_read", lambda p: p.fins_write_access_log_read()),
    ("fins_write_access_log_clear", lambda p: p.fins_write_access_log_clear()),
    ("file_memory_format", lambda p: p.file_memory_format("card")),
    ("single_file_write", lambda p: p.single_file_write("card", "A.TXT", bytearray(b"hello"))),
    ("file_name_read", lambda p: p.file_name_read("memory_card")),
    ("single_file_read", lambda p: p.single_file_read("card", "A.TXT")),
    ("file_copy", lambda p: p.file_copy("card", "A.TXT", "card", "B.TXT")),
    ("file_name_change", lambda p: p.file_name_change("card", "B.TXT", "C.TXT")),
    ("file_delete", lambda p: p.file_delete("card", "C.TXT")),
    ("create_delete_directory", lambda p: p.create_delete_directory("card", "create", "LOGS")),
    (
        "memory_area_file_transfer",
        lambda p: p.memory_area_file_transfer("area_to_file", "D0", 10, "card", "DM.IOM"),
    ),
    (
        "parameter_area_file_transfer",
        lambda p: p.parameter_area_file_transfer("area-to-file", "plc_setup", "card", "SET.STD"),
    ),
    (
        "program_area_file_transfer",
        lambda p: p.program_area_file_transfer("AREA_TO_FILE", "card", "PROG.OBJ"),
    ),
    ("memory_cassette_transfer", lambda p: p.memory_cassette_transfer("read_data_type")),
    ("forced_set_reset", lambda p: p.forced_set_reset([("forced_set", "CIO 0.01")])),
    ("forced_set_reset_cancel", lambda p: p.forced_set_reset_cancel()),
    (
        "convert_to_compoway_f_command",
        lambda p: p.convert_to_compoway_f_command(
            list(ConvertToCompowayFCommand.build(1, "0101", b"C0000000").payload)
        ),
    ),
    (
        "convert_to_modbus_rtu_command",
        lambda p: p.convert_to_modbus_rtu_command(
            bytearray(ConvertToModbusRtuCommand.build(1, 3, bytes.fromhex("00000002")).payload)
        ),
    ),
    (
        "convert_to_modbus_ascii_command",
        lambda p: p.convert_to_modbus_ascii_command(
            ConvertToModbusAsciiCommand.build(1, 3, bytes.fromhex("00000002")).payload
        ),
    ),
    ("run", lambda p: p.run("run")),
    ("cycle_time_read", lambda p: p.cycle_time_read("read")),
    ("stop", lambda p: p.stop()),
]


def test_text_script_covers_all_47_operations() -> None:
    assert sorted(name for name, _ in TEXT_SCRIPT) == sorted(op.METHOD for op in ALL_OPERATIONS)


async def test_every_operation_takes_text_arguments(url: str, sim: Simulator) -> None:
    plc_state = sim.plc
    assert isinstance(plc_state, VirtualPLC)
    outcomes: dict[str, Any] = {}
    async with aiofins.connect(url, timeout=2, retries=0) as plc:
        for name, step in TEXT_SCRIPT:
            try:
                outcomes[name] = await step(plc)
            except aiofins.EndCodeError as exc:
                assert EXPECTED_END_CODES.get(name) == exc.end_code.code, f"{name}: {exc}"
        typed = await plc.multiple_memory_area_read(
            (parse_address("D0"), parse_address("D5"), parse_address("CIO 1.02"))
        )
    # Typed results, the same as with typed arguments.
    assert outcomes["memory_area_read"].values == (7, 8)
    assert outcomes["multiple_memory_area_read"] == typed
    assert plc_state.read("D200", 50) == [7] * 50 and plc_state.read("D300", 5) == [7] * 5
    assert outcomes["clock_read"].time == datetime(2026, 1, 2, 3, 4, 5)
    assert outcomes["program_area_read"].data == bytes([1, 2, 3, 4] * 2)
    assert plc_state.read("CIO 0.01") == [1]  # force-set (the cancel keeps it ON)


async def test_text_that_names_nothing_is_refused(url: str) -> None:
    async with aiofins.connect(url) as plc:
        untyped: Any = plc
        for call, said in (
            (untyped.memory_area_read(12, 1), "address must be address text such as 'D100'"),
            (untyped.memory_area_write("D0", "56"), "data must be bytes or a list of ints"),
            (untyped.memory_area_write("D0", [70000]), r"data value 70000 out of range 0\.\.65535"),
            (untyped.file_name_read("floppy"), "disk must be one of memory_card, "),
            (untyped.run("fast"), "mode must be one of monitor, run; got 'fast'"),
            (untyped.clock_write("tomorrow"), "time must be a datetime or ISO text"),
            (untyped.forced_set_reset([("on", "CIO 0.01")]), "designation must be one of"),
        ):
            with pytest.raises(aiofins.CommandError, match=said):
                await call
        with pytest.raises(aiofins.AddressError):
            await plc.multiple_memory_area_read(["D0", "Q5"])
    assert Disk.MEMORY_CARD.name == "MEMORY_CARD"
