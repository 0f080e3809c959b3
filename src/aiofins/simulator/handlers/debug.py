"""Forced set/reset: 2301 FORCED SET/RESET, 2302 FORCED SET/RESET CANCEL (5-3-44, 5-3-45)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.debug import ForcedSetReset, ForcedSetResetCancel
from ..codes import by_command_code
from ..memory import FORCE_AREAS
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC


def forced_set_reset(plc: VirtualPLC, call: Call) -> bytes:
    req = request_of(call, ForcedSetReset)
    for e in req.entries:  # validate every address before forcing anything
        a = e.address
        plc.memory.locate(plc.memory.area(a.area_code, FORCE_AREAS), a.word, a.bit, 1)
    for e in req.entries:
        plc.memory.force(e.address.area_code, e.address.word, e.address.bit, int(e.spec))
    return b""


def forced_set_reset_cancel(plc: VirtualPLC, call: Call) -> bytes:
    request_of(call, ForcedSetResetCancel)
    plc.memory.cancel_forces()
    return b""


HANDLERS: dict[int, Handler] = by_command_code(
    {ForcedSetReset: forced_set_reset, ForcedSetResetCancel: forced_set_reset_cancel}
)
