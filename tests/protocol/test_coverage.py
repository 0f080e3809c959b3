"""Every command of manual 5-1-1 has a request builder, a parser and a client method name."""

from __future__ import annotations

import dataclasses
import re

import pytest

from aiofins.protocol.commands import ALL_OPERATIONS, COMMAND_CODES, Request, operation_for

# Manual 5-1-1, in its order: (command code, manual name, method). 09 20 carries three
# operations (5-3-21..5-3-23); 47 operations on 45 command codes.
MANUAL_OPERATIONS: list[tuple[int, str, str]] = [
    (0x0101, "MEMORY AREA READ", "memory_area_read"),
    (0x0102, "MEMORY AREA WRITE", "memory_area_write"),
    (0x0103, "MEMORY AREA FILL", "memory_area_fill"),
    (0x0104, "MULTIPLE MEMORY AREA READ", "multiple_memory_area_read"),
    (0x0105, "MEMORY AREA TRANSFER", "memory_area_transfer"),
    (0x0201, "PARAMETER AREA READ", "parameter_area_read"),
    (0x0202, "PARAMETER AREA WRITE", "parameter_area_write"),
    (0x0203, "PARAMETER AREA CLEAR", "parameter_area_clear"),
    (0x0306, "PROGRAM AREA READ", "program_area_read"),
    (0x0307, "PROGRAM AREA WRITE", "program_area_write"),
    (0x0308, "PROGRAM AREA CLEAR", "program_area_clear"),
    (0x0401, "RUN", "run"),
    (0x0402, "STOP", "stop"),
    (0x0501, "CPU UNIT DATA READ", "cpu_unit_data_read"),
    (0x0502, "CONNECTION DATA READ", "connection_data_read"),
    (0x0601, "CPU UNIT STATUS READ", "cpu_unit_status_read"),
    (0x0620, "CYCLE TIME READ", "cycle_time_read"),
    (0x0701, "CLOCK READ", "clock_read"),
    (0x0702, "CLOCK WRITE", "clock_write"),
    (0x0920, "MESSAGE READ", "message_read"),
    (0x0920, "MESSAGE CLEAR", "message_clear"),
    (0x0920, "FAL/FALS READ", "fal_fals_read"),
    (0x0C01, "ACCESS RIGHT ACQUIRE", "access_right_acquire"),
    (0x0C02, "ACCESS RIGHT FORCED ACQUIRE", "access_right_forced_acquire"),
    (0x0C03, "ACCESS RIGHT RELEASE", "access_right_release"),
    (0x2101, "ERROR CLEAR", "error_clear"),
    (0x2102, "ERROR LOG READ", "error_log_read"),
    (0x2103, "ERROR LOG CLEAR", "error_log_clear"),
    (0x2140, "FINS WRITE ACCESS LOG READ", "fins_write_access_log_read"),
    (0x2141, "FINS WRITE ACCESS LOG CLEAR", "fins_write_access_log_clear"),
    (0x2201, "FILE NAME READ", "file_name_read"),
    (0x2202, "SINGLE FILE READ", "single_file_read"),
    (0x2203, "SINGLE FILE WRITE", "single_file_write"),
    (0x2204, "FILE MEMORY FORMAT", "file_memory_format"),
    (0x2205, "FILE DELETE", "file_delete"),
    (0x2207, "FILE COPY", "file_copy"),
    (0x2208, "FILE NAME CHANGE", "file_name_change"),
    (0x220A, "MEMORY AREA-FILE TRANSFER", "memory_area_file_transfer"),
    (0x220B, "PARAMETER AREA-FILE TRANSFER", "parameter_area_file_transfer"),
    (0x220C, "PROGRAM AREA-FILE TRANSFER", "program_area_file_transfer"),
    (0x2215, "CREATE/DELETE DIRECTORY", "create_delete_directory"),
    (0x2220, "MEMORY CASSETTE TRANSFER", "memory_cassette_transfer"),
    (0x2301, "FORCED SET/RESET", "forced_set_reset"),
    (0x2302, "FORCED SET/RESET CANCEL", "forced_set_reset_cancel"),
    (0x2803, "CONVERT TO COMPOWAY/F COMMAND", "convert_to_compoway_f_command"),
    (0x2804, "CONVERT TO MODBUS-RTU COMMAND", "convert_to_modbus_rtu_command"),
    (0x2805, "CONVERT TO MODBUS-ASCII COMMAND", "convert_to_modbus_ascii_command"),
]


def _normalise(name: str) -> str:
    return re.sub(r"[^A-Z/]", "", name.upper().replace("\u2013", "-"))


def test_manual_counts() -> None:
    assert len(MANUAL_OPERATIONS) == 47
    assert len({code for code, _, _ in MANUAL_OPERATIONS}) == 45


def test_every_operation_implemented_once() -> None:
    assert len(ALL_OPERATIONS) == 47
    assert {code for code, _, _ in MANUAL_OPERATIONS} == COMMAND_CODES
    implemented = {(op.command_code(), op.METHOD) for op in ALL_OPERATIONS}
    expected = {(code, method) for code, _, method in MANUAL_OPERATIONS}
    assert implemented == expected
    assert len({op.METHOD for op in ALL_OPERATIONS}) == 47


@pytest.mark.parametrize(
    ("code", "name", "method"), MANUAL_OPERATIONS, ids=[m for _, _, m in MANUAL_OPERATIONS]
)
def test_operation_has_builder_and_parser(code: int, name: str, method: str) -> None:
    matches = [op for op in ALL_OPERATIONS if method == op.METHOD]
    assert len(matches) == 1, f"{code:04X} {name}: no operation named {method}"
    op = matches[0]
    assert op.command_code() == code
    assert _normalise(op.NAME) == _normalise(name)
    assert dataclasses.is_dataclass(op)
    # The builder, the server-side parser and the response parser are all overridden.
    for attr in ("encode", "decode", "decode_response"):
        assert getattr(op, attr) is not getattr(Request, attr), f"{method} lacks {attr}"


def test_message_variants_dispatch_by_parameter_bits() -> None:
    read = operation_for(0x09, 0x20, bytes((0x00, 0x01)))
    clear = operation_for(0x09, 0x20, bytes((0x40, 0x01)))
    fal = operation_for(0x09, 0x20, bytes((0x80, 0x01)))
    assert (read.METHOD, clear.METHOD, fal.METHOD) == (
        "message_read",
        "message_clear",
        "fal_fals_read",
    )
