"""Parameter area access: 0201 read, 0202 write, 0203 clear (manual 5-3-7 to 5-3-9).

The areas live in one 8,000-word store (code 8000); the PLC Setup (8010), I/O table
(8012), routing tables (8013) and CPU Bus Unit Setup (8002) are views of it, laid out in
that order (the manual gives no layout; this is the simulator's choice).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.codec import Reader
from ...protocol.commands.parameter import (
    LAST_WORD,
    MAX_PARAMETER_WORDS,
    PARAMETER_AREA_WORDS,
    ParameterArea,
    ParameterAreaClear,
    ParameterAreaRead,
    ParameterAreaReadResult,
    ParameterAreaWrite,
)
from ..codes import by_command_code
from ..restrictions import MODE_END_CODES
from ..state import (
    ADDRESS_RANGE_ERROR,
    ADDRESS_RANGE_EXCEEDED,
    AREA_MISSING,
    PARAMETER_ERROR,
    TOO_MANY_WORDS,
    CommandFailed,
    Mode,
)
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC

MAX_WORDS = MAX_PARAMETER_WORDS
IO_TABLE = ParameterArea.IO_TABLE


def _layout(*order: ParameterArea) -> dict[int, tuple[int, int]]:
    """8000 spans the whole store; the other areas lie end to end from word 0, in ``order``."""
    out: dict[int, tuple[int, int]] = {
        ParameterArea.ALL: (0, PARAMETER_AREA_WORDS[ParameterArea.ALL])
    }
    base = 0
    for area in order:
        out[area] = (base, PARAMETER_AREA_WORDS[area])
        base += PARAMETER_AREA_WORDS[area]
    return out


#: Parameter area code → (first word in the 8000 store, number of words).
LAYOUT = _layout(
    ParameterArea.PLC_SETUP,
    ParameterArea.IO_TABLE,
    ParameterArea.ROUTING_TABLES,
    ParameterArea.CPU_BUS_UNIT_SETUP,
)


def _area(code: int) -> tuple[int, int]:
    try:
        return LAYOUT[code]
    except KeyError:
        raise CommandFailed(AREA_MISSING, message=f"parameter area {code:04X}") from None


def _check_io_table_mode(plc: VirtualPLC, code: int) -> None:
    # manual 5-3-8/5-3-9: the I/O table is written or cleared only in PROGRAM mode
    if code == IO_TABLE and plc.mode is not Mode.PROGRAM:
        raise CommandFailed(MODE_END_CODES[plc.mode])


def parameter_area_read(plc: VirtualPLC, call: Call) -> bytes:
    r = Reader(call.params, "PARAMETER AREA READ")
    code, begin, count = r.u16(), r.u16(), r.u16()
    r.end()
    base, size = _area(code)
    if count & LAST_WORD:
        raise CommandFailed(PARAMETER_ERROR, message="bit 15 of the word count must be 0")
    if begin >= size:
        raise CommandFailed(ADDRESS_RANGE_ERROR)
    end_code = 0
    n = count
    if n > MAX_WORDS:
        n, end_code = MAX_WORDS, TOO_MANY_WORDS
    if begin + n > size:
        n, end_code = size - begin, ADDRESS_RANGE_EXCEEDED
    start = 2 * (base + begin)
    raw = plc.parameter_memory[start : start + 2 * n]
    words = tuple(int.from_bytes(raw[i : i + 2], "big") for i in range(0, len(raw), 2))
    out = ParameterAreaReadResult(code, begin, words, begin + n == size).encode()
    if end_code:
        raise CommandFailed(end_code, out)
    return out


def parameter_area_write(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ParameterAreaWrite)
    code, begin, count = req.area_code, req.begin_word, len(req.words)
    base, size = _area(code)
    if count == 0:
        return b""
    if count > MAX_WORDS:
        raise CommandFailed(PARAMETER_ERROR, message="more than 498 words: nothing written")
    if begin >= size:
        raise CommandFailed(ADDRESS_RANGE_ERROR)
    if begin + count > size:
        raise CommandFailed(ADDRESS_RANGE_EXCEEDED)
    _check_io_table_mode(plc, code)
    if begin + count == size and not req.last:
        # manual 5-3-8: without bit 15 on the block with the last word, nothing is written
        return b""
    start = 2 * (base + begin)
    plc.parameter_memory[start : start + 2 * count] = b"".join(
        w.to_bytes(2, "big") for w in req.words
    )
    return b""


def parameter_area_clear(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ParameterAreaClear)
    base, size = _area(req.area_code)
    count = size if req.count is None else req.count
    if count == 0:
        return b""
    if count > size:
        raise CommandFailed(ADDRESS_RANGE_EXCEEDED)
    if count != size:
        raise CommandFailed(PARAMETER_ERROR, message="a parameter area is cleared whole")
    _check_io_table_mode(plc, req.area_code)
    plc.parameter_memory[2 * base : 2 * (base + size)] = bytes(2 * size)
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        ParameterAreaRead: parameter_area_read,
        ParameterAreaWrite: parameter_area_write,
        ParameterAreaClear: parameter_area_clear,
    }
)
