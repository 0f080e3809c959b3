"""Messages (0920 read / clear / FAL-FALS read) and the access right (0C01, 0C02, 0C03).

The access right belongs to a source address (network, node, unit). 0C01 from another node
while it is held is refused by the restriction check with ``3001`` and the holder's
network, node and unit after the end code (manual 5-3-24; wire-format §9.1 byte order).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.access import (
    AccessRightAcquire,
    AccessRightForcedAcquire,
    AccessRightRelease,
)
from ...protocol.commands.message import (
    FalFalsMessage,
    FalFalsRead,
    MessageClear,
    MessageRead,
    Messages,
)
from ...protocol.commands.program import PROGRAM_NUMBER
from ..codes import by_command_code
from ..state import PARAMETER_ERROR, PROGRAM_NUMBER_MISSING, CommandFailed
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC

MESSAGE_SIZE = 32
FAL_MESSAGE_SIZE = 16
MAX_FAL = 511


def _ascii(text: str, size: int) -> str:
    """A stored message as the PLC holds it: ASCII, cut to the field size."""
    return text.encode("ascii", "replace").decode("ascii")[:size]


def message_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MessageRead)
    numbers = [n for n in range(8) if req.mask & (1 << n)]
    texts = tuple(_ascii(plc.messages.get(n, ""), MESSAGE_SIZE) for n in numbers)
    return Messages(req.mask & 0xFF, texts).encode()


def message_clear(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, MessageClear)
    for n in range(8):
        if req.mask & (1 << n):
            plc.messages.pop(n, None)
    return b""


def fal_fals_read(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, FalFalsRead)
    if not 1 <= req.number <= MAX_FAL:
        raise CommandFailed(PARAMETER_ERROR, message=f"FAL/FALS number {req.number}")
    text = _ascii(plc.fal_messages.get(req.number, ""), FAL_MESSAGE_SIZE)
    return FalFalsMessage(req.number, text).encode()


def message(plc: VirtualPLC, call: Call) -> bytes:
    """0920: the three operations share the code; the codec tells which one was sent."""
    if isinstance(call.request, MessageClear):
        return message_clear(plc, call)
    if isinstance(call.request, FalFalsRead):
        return fal_fals_read(plc, call)
    return message_read(plc, call)


def _check_program_number(number: int) -> None:
    if number != PROGRAM_NUMBER:  # 1106: FFFF hex was not specified (manual 5-1-3)
        raise CommandFailed(PROGRAM_NUMBER_MISSING, message="program number must be FFFF")


def access_right_acquire(plc: VirtualPLC, call: Call) -> bytes:
    _check_program_number(request_of(call, AccessRightAcquire).program_number)
    plc.access_holder = call.source  # the restriction check refused it if held elsewhere
    return b""


def access_right_forced_acquire(plc: VirtualPLC, call: Call) -> bytes:
    _check_program_number(request_of(call, AccessRightForcedAcquire).program_number)
    plc.access_holder = call.source  # the previous holder is not told
    return b""


def access_right_release(plc: VirtualPLC, call: Call) -> bytes:
    _check_program_number(request_of(call, AccessRightRelease).program_number)
    plc.access_holder = None  # normal whoever holds it, or if nobody does
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {
        MessageRead: message,
        MessageClear: message,
        FalFalsRead: message,
        AccessRightAcquire: access_right_acquire,
        AccessRightForcedAcquire: access_right_forced_acquire,
        AccessRightRelease: access_right_release,
    }
)
