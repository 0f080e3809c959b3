"""Small shared pieces of the virtual PLC: operating mode, the handler failure, end codes."""

from __future__ import annotations

from enum import IntEnum

from ..protocol import decoding, endcodes
from ..protocol.commands.status import CpuMode


class Mode(IntEnum):
    """CPU Unit operating mode, with the values 0601 and 0401 use on the wire (no CV DEBUG)."""

    #: Stopped: every write is accepted, the program does not run.
    PROGRAM = CpuMode.PROGRAM.value
    #: Running, online changes accepted.
    MONITOR = CpuMode.MONITOR.value
    #: Running, online changes refused as a real CPU refuses them.
    RUN = CpuMode.RUN.value


class CommandFailed(Exception):
    """A command handler's non-normal answer: the end code and any response data with it."""

    def __init__(self, end_code: int, data: bytes = b"", message: str = "") -> None:
        super().__init__(message or f"end code {end_code:04X}")
        self.end_code = end_code
        self.data = data


#: Records kept by the error log and by the FINS write access log (manual 5-3-28, 5-3-30).
LOG_CAPACITY = 20

# End codes the simulator answers (manual 5-1-3): the one place in simulator/ that names
# them. Codes the protocol core already names are taken from it; the rest are written once
# here, and every code but 1108 is a row of ``protocol.endcodes.END_CODES``.
NORMAL = endcodes.NORMAL.raw
UNDEFINED_COMMAND = 0x0401
#: Destination address setting error (routing table): answered for another network.
NO_ROUTE = 0x0501
COMMAND_TOO_SHORT = 0x1002
AREA_MISSING = 0x1101
ADDRESS_RANGE_ERROR = 0x1103
ADDRESS_RANGE_EXCEEDED = 0x1104
PROGRAM_NUMBER_MISSING = 0x1106
#: Not in the 5-1-3 table: 0201 asked for more than 498 words, 498 returned (manual 5-3-7).
TOO_MANY_WORDS = 0x1108
RESPONSE_TOO_LONG = 0x110B
PARAMETER_ERROR = decoding.PARAMETER_ERROR
#: Read not possible: protected (UM read protection).
UM_READ_PROTECTED = 0x2002
READ_FILE_MISSING = 0x2006
DATA_MISMATCH = 0x2007
READ_ONLY = 0x2101
#: Write not possible: read-only, "protected using a switch setting" (DIP-switch pin 1).
UM_WRITE_PROTECTED = READ_ONLY
#: Write not possible: protected (network write protection, manual 5-1-1 note 1).
NETWORK_WRITE_PROTECTED = 0x2102
CANNOT_REGISTER = 0x2103
WRITE_FILE_MISSING = 0x2106
FILE_EXISTS = 0x2107
CANNOT_CHANGE = 0x2108
#: Wrong PLC mode, by the mode the PLC is in.
WRONG_MODE_PROGRAM = 0x2203
WRONG_MODE_MONITOR = 0x2205
WRONG_MODE_RUN = 0x2206
FILE_DEVICE_MISSING = 0x2301
#: Command error 2604: "already processing 5 commands" (also "the area is protected").
BUSY = 0x2604
#: No access right: another node holds it.
ACCESS_RIGHT_HELD = 0x3001
