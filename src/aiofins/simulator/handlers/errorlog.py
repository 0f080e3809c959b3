"""Error clear and logs: 2101, 2102, 2103, 2140, 2141 (manual 5-3-27 to 5-3-31)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.errorlog import (
    CLEAR_ALL_ERRORS,
    CLEAR_CURRENT_ERROR,
    ErrorClear,
    ErrorLog,
    ErrorLogClear,
    ErrorLogRead,
    ErrorLogRecord,
    FinsWriteAccessLog,
    FinsWriteAccessLogClear,
    FinsWriteAccessLogRead,
    FinsWriteAccessRecord,
)
from ..codes import by_command_code
from ..restrictions import MODE_END_CODES
from ..state import (
    ADDRESS_RANGE_ERROR,
    ADDRESS_RANGE_EXCEEDED,
    LOG_CAPACITY,
    CommandFailed,
    Mode,
)
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC

#: Error codes ERROR CLEAR accepts only in PROGRAM mode (5-3-27's second table).
_PROGRAM_ONLY = frozenset(
    (
        CLEAR_ALL_ERRORS,
        0x809F,
        *range(0x80C0, 0x80C8),
        0x80E0,
        0x80E1,
        0x80E9,
        0x80EA,
        0x80F0,
        0x80F1,
    )
) | frozenset((0x82F0, *range(0xC101, 0xC300)))
MAX_RESPONSE_DATA = 1998


def error_clear(plc: VirtualPLC, call: Call) -> bytes:
    code = request_of(call, ErrorClear).error_code
    serious = plc.most_serious_error()
    target = serious if code == CLEAR_CURRENT_ERROR and serious is not None else code
    if (code in _PROGRAM_ONLY or target in _PROGRAM_ONLY) and plc.mode is not Mode.PROGRAM:
        raise CommandFailed(MODE_END_CODES[plc.mode], message="clearable in PROGRAM mode only")
    if code == CLEAR_ALL_ERRORS:
        plc.current_errors.clear()
    elif target in plc.current_errors:  # normal end even when the error is not present
        plc.current_errors.remove(target)
    plc.refresh_error_state()
    return b""


def _window(stored: int, begin: int, count: int, record_size: int) -> tuple[int, bool]:
    available = max(stored - begin, 0)
    # data beyond the response's length is left out with a normal end (5-3-28, 5-3-30)
    n = min(count, available, (MAX_RESPONSE_DATA - 6) // record_size)
    return n, count > available


def error_log_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ErrorLogRead)
    begin, stored = req.beginning_record, len(plc.error_log)
    if begin > stored:
        raise CommandFailed(ADDRESS_RANGE_ERROR)  # manual: command code and end code only
    n, short = _window(stored, begin, req.count, 10)
    records = tuple(
        ErrorLogRecord(r.code1, r.code2, r.time.replace(microsecond=0))
        for r in plc.error_log[begin : begin + n]
    )
    data = ErrorLog(LOG_CAPACITY, stored, records).encode()
    if short:  # fewer records than asked: what exists, with an address range error
        raise CommandFailed(ADDRESS_RANGE_EXCEEDED, data)
    return data


def error_log_clear(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, ErrorLogClear)
    plc.error_log.clear()
    return b""


def fins_write_access_log_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, FinsWriteAccessLogRead)
    begin, stored = req.beginning_record, len(plc.write_log)
    if begin > stored:
        raise CommandFailed(ADDRESS_RANGE_ERROR)  # manual 5-3-30: 1103
    n, _short = _window(stored, begin, req.count, 12)  # fewer than asked: normal end
    records = tuple(
        FinsWriteAccessRecord(
            r.source.network,
            r.source.node,
            r.source.unit,
            r.command_code,
            r.time.replace(microsecond=0),
            r.weekday,
        )
        for r in plc.write_log[begin : begin + n]
    )
    return FinsWriteAccessLog(LOG_CAPACITY, stored, records).encode()


def fins_write_access_log_clear(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, FinsWriteAccessLogClear)
    plc.write_log.clear()
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        ErrorClear: error_clear,
        ErrorLogRead: error_log_read,
        ErrorLogClear: error_log_clear,
        FinsWriteAccessLogRead: fins_write_access_log_read,
        FinsWriteAccessLogClear: fins_write_access_log_clear,
    }
)
