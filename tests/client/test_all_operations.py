"""Every one of the 47 operations, sent by the client and answered by the virtual PLC, over
UDP, FINS/TCP (here) and Host Link (test_serial.py runs the same script)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from datetime import datetime
from typing import Any

import pytest

from aiofins.client import Client
from aiofins.connection import connect
from aiofins.protocol.addresses import parse_address
from aiofins.protocol.commands import ALL_OPERATIONS
from aiofins.protocol.commands.debug import ForcedSetResetEntry, ForceSpec
from aiofins.protocol.commands.gateway import (
    ConvertToCompowayFCommand,
    ConvertToModbusAsciiCommand,
    ConvertToModbusRtuCommand,
)
from aiofins.protocol.errors import EndCodeError
from aiofins.protocol.files import CassetteOperation, DirectoryOperation, Disk, FileTransferMode

pytestmark = pytest.mark.anyio

D = parse_address
CARD = Disk.MEMORY_CARD

Step = tuple[str, Callable[[Client], Awaitable[Any]]]

SCRIPT: list[Step] = [
    ("memory_area_write", lambda p: p.memory_area_write(D("D0"), b"\x00\x07\x00\x08")),
    ("memory_area_read", lambda p: p.memory_area_read(D("D0"), 2)),
    ("memory_area_fill", lambda p: p.memory_area_fill(D("D10"), 5, 0x1234)),
    ("multiple_memory_area_read", lambda p: p.multiple_memory_area_read((D("D0"), D("D10")))),
    ("memory_area_transfer", lambda p: p.memory_area_transfer(D("D10"), D("D20"), 5)),
    ("parameter_area_read", lambda p: p.parameter_area_read(0x8010, 0, 10)),
    ("parameter_area_write", lambda p: p.parameter_area_write(0x8010, 0, tuple(range(10)))),
    ("parameter_area_clear", lambda p: p.parameter_area_clear(0x8013)),
    ("program_area_write", lambda p: p.program_area_write(0, b"\x01\x02\x03\x04" * 2)),
    ("program_area_read", lambda p: p.program_area_read(0, 8)),
    ("program_area_clear", lambda p: p.program_area_clear()),
    ("cpu_unit_data_read", lambda p: p.cpu_unit_data_read()),
    ("connection_data_read", lambda p: p.connection_data_read()),
    ("cpu_unit_status_read", lambda p: p.cpu_unit_status_read()),
    ("clock_write", lambda p: p.clock_write(datetime(2026, 1, 2, 3, 4, 5))),
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
    ("file_memory_format", lambda p: p.file_memory_format(CARD)),
    ("single_file_write", lambda p: p.single_file_write(CARD, "A.TXT", b"hello")),
    ("file_name_read", lambda p: p.file_name_read(CARD)),
    ("single_file_read", lambda p: p.single_file_read(CARD, "A.TXT")),
    ("file_copy", lambda p: p.file_copy(CARD, "A.TXT", CARD, "B.TXT")),
    ("file_name_change", lambda p: p.file_name_change(CARD, "B.TXT", "C.TXT")),
    ("file_delete", lambda p: p.file_delete(CARD, ("C.TXT",))),
    (
        "create_delete_directory",
        lambda p: p.create_delete_directory(CARD, DirectoryOperation.CREATE, "LOGS"),
    ),
    (
        "memory_area_file_transfer",
        lambda p: p.memory_area_file_transfer(
            FileTransferMode.AREA_TO_FILE, D("D0"), 10, CARD, "DM.IOM"
        ),
    ),
    (
        "parameter_area_file_transfer",
        lambda p: p.parameter_area_file_transfer(
            FileTransferMode.AREA_TO_FILE, 0x8010, CARD, "SETUP.STD"
        ),
    ),
    (
        "program_area_file_transfer",
        lambda p: p.program_area_file_transfer(FileTransferMode.AREA_TO_FILE, CARD, "PROG.OBJ"),
    ),
    (
        "memory_cassette_transfer",
        lambda p: p.memory_cassette_transfer(CassetteOperation.READ_DATA_TYPE),
    ),
    (
        "forced_set_reset",
        lambda p: p.forced_set_reset((ForcedSetResetEntry(ForceSpec.FORCED_SET, D("CIO 0.01")),)),
    ),
    ("forced_set_reset_cancel", lambda p: p.forced_set_reset_cancel()),
    (
        "convert_to_compoway_f_command",
        lambda p: p.convert_to_compoway_f_command(
            ConvertToCompowayFCommand.build(1, "0101", b"C0000000").payload
        ),
    ),
    (
        "convert_to_modbus_rtu_command",
        lambda p: p.convert_to_modbus_rtu_command(
            ConvertToModbusRtuCommand.build(1, 3, bytes.fromhex("00000002")).payload
        ),
    ),
    (
        "convert_to_modbus_ascii_command",
        lambda p: p.convert_to_modbus_ascii_command(
            ConvertToModbusAsciiCommand.build(1, 3, bytes.fromhex("00000002")).payload
        ),
    ),
    ("run", lambda p: p.run()),
    ("cycle_time_read", lambda p: p.cycle_time_read()),  # RUN/MONITOR only (5-3-17)
    ("stop", lambda p: p.stop()),
]

#: Operations a CJ2 CPU answers with an end code here, by design of the manual.
EXPECTED_END_CODES: dict[str, int] = {
    # 2220 exists on CP1H/CP1L only; the simulated CJ2M answers "undefined command".
    "memory_cassette_transfer": 0x0401,
}


async def run_script(plc: Client) -> dict[str, object]:
    outcomes: dict[str, object] = {}
    for name, step in SCRIPT:
        try:
            outcomes[name] = await step(plc)
        except EndCodeError as exc:
            outcomes[name] = exc
    return outcomes


def test_script_covers_all_47_operations() -> None:
    assert sorted(name for name, _ in SCRIPT) == sorted(op.METHOD for op in ALL_OPERATIONS)


async def test_every_operation_is_answered(url: str) -> None:
    async with connect(url, timeout=2, retries=0) as plc:
        outcomes = await run_script(plc)
    failures = {
        name: f"{out.end_code.code:04X} {out.end_code.name}"
        for name, out in outcomes.items()
        if isinstance(out, EndCodeError) and EXPECTED_END_CODES.get(name) != out.end_code.code
    }
    assert failures == {}
    assert outcomes["memory_area_read"].values == (7, 8)  # type: ignore[attr-defined]
    assert outcomes["clock_read"].time.year == 2026  # type: ignore[attr-defined]
