"""Program area (0306 read, 0307 write, 0308 clear) and operating mode (0401 RUN, 0402 STOP).

The program area (UM) is a byte array. ``plc.program_length`` is the end of the stored
program: it is set by the 0307 block carrying bit 15 ("last word") and is what bit 15 of a
0306 response reports ("the data at the last address in the program area is included").
The codec checks the program number (FFFF), alignment and sizes before a handler runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.mode import Run, Stop
from ...protocol.commands.program import (
    ProgramAreaClear,
    ProgramAreaRead,
    ProgramAreaReadResult,
    ProgramAreaWrite,
    ProgramAreaWriteResult,
)
from ..codes import by_command_code
from ..state import (
    ADDRESS_RANGE_ERROR,
    ADDRESS_RANGE_EXCEEDED,
    PARAMETER_ERROR,
    CommandFailed,
    Mode,
)
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC


def _check_block(plc: VirtualPLC, begin: int, n: int) -> None:
    if begin >= len(plc.program):
        raise CommandFailed(ADDRESS_RANGE_ERROR)
    if begin + n > len(plc.program):
        raise CommandFailed(ADDRESS_RANGE_EXCEEDED)


def program_area_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ProgramAreaRead)
    begin, n = req.address, req.byte_count
    _check_block(plc, begin, n)
    last = begin + n >= plc.program_length
    return ProgramAreaReadResult(begin, bytes(plc.program[begin : begin + n]), last).encode()


def program_area_write(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ProgramAreaWrite)
    begin, data = req.address, req.data
    _check_block(plc, begin, len(data))
    plc.program[begin : begin + len(data)] = data
    if req.last:
        end = begin + len(data)
        plc.program_length = end
        plc.program[end:] = bytes(len(plc.program) - end)  # nothing of a longer old program
    else:
        plc.program_length = max(plc.program_length, begin + len(data))
    return ProgramAreaWriteResult(begin, len(data), req.last).encode()


def program_area_clear(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, ProgramAreaClear)
    plc.program[:] = bytes(len(plc.program))
    plc.program_length = 0
    plc.um_read_protected = False  # manual 5-3-12: clearing also clears the protection
    return b""


def run(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, Run)  # manual 5-3-13: no mode given → MONITOR (the codec's default)
    if int(req.mode) not in (Mode.MONITOR, Mode.RUN):  # CV's DEBUG mode does not exist
        raise CommandFailed(PARAMETER_ERROR, message=f"mode {int(req.mode):02X}")
    if plc.mode is Mode.PROGRAM:
        plc.start_operation()
    plc.mode = Mode(int(req.mode))
    return b""


def stop(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, Stop)
    plc.mode = Mode.PROGRAM
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        ProgramAreaRead: program_area_read,
        ProgramAreaWrite: program_area_write,
        ProgramAreaClear: program_area_clear,
        Run: run,
        Stop: stop,
    }
)
