"""Command handlers of the virtual PLC, one module per command family.

A handler takes the PLC and a :class:`Call` (command code, parameter bytes, source address)
and returns the response data after the end code; a non-normal answer raises
:class:`~aiofins.simulator.state.CommandFailed` (or the codec's ``DecodeError``).
Execution conditions (manual 5-1-2) are checked by the PLC before a handler runs.
"""

from __future__ import annotations

from ...protocol.commands.file import MemoryCassetteTransfer
from ..codes import Operation
from ._call import Call, GatewayHandler, Handler
from .access import HANDLERS as _ACCESS
from .debug import HANDLERS as _DEBUG
from .errorlog import HANDLERS as _ERRORLOG
from .file import HANDLERS as _FILE
from .gateway import HANDLERS as _GATEWAY
from .gateway import default_gateway
from .machine import HANDLERS as _MACHINE
from .memory import HANDLERS as _MEMORY
from .parameter import HANDLERS as _PARAMETER
from .program import HANDLERS as _PROGRAM

#: Operations the virtual PLC has no handler for: a CJ2M has no Memory Cassette, so 2220
#: is answered ``0401`` (undefined command) before any other check.
UNANSWERED: tuple[Operation, ...] = (MemoryCassetteTransfer,)

#: Command code → handler, for every command the virtual PLC answers.
HANDLERS: dict[int, Handler] = {
    **_MEMORY,
    **_PARAMETER,
    **_PROGRAM,
    **_MACHINE,
    **_ACCESS,
    **_ERRORLOG,
    **_FILE,
    **_DEBUG,
    **_GATEWAY,
}

__all__ = ["HANDLERS", "UNANSWERED", "Call", "GatewayHandler", "Handler", "default_gateway"]
