"""Small shared pieces of the virtual PLC: operating mode, the handler failure, end codes."""

from __future__ import annotations

from enum import IntEnum


class Mode(IntEnum):
    """CPU Unit operating mode, with the values 0601 and 0401 use on the wire."""

    PROGRAM = 0x00
    MONITOR = 0x02
    RUN = 0x04


class CommandFailed(Exception):
    """A command handler's non-normal answer: the end code and any response data with it."""

    def __init__(self, end_code: int, data: bytes = b"", message: str = "") -> None:
        super().__init__(message or f"end code {end_code:04X}")
        self.end_code = end_code
        self.data = data


#: Records kept by the error log and by the FINS write access log (manual 5-3-28, 5-3-30).
LOG_CAPACITY = 20

# End codes the simulator answers (manual 5-1-3; the restriction table's are in
# restrictions.py).
NORMAL = 0x0000
UNDEFINED_COMMAND = 0x0401
COMMAND_TOO_SHORT = 0x1002
AREA_MISSING = 0x1101
ADDRESS_RANGE_ERROR = 0x1103
ADDRESS_RANGE_EXCEEDED = 0x1104
PROGRAM_NUMBER_MISSING = 0x1106
RESPONSE_TOO_LONG = 0x110B
PARAMETER_ERROR = 0x110C
READ_FILE_MISSING = 0x2006
DATA_MISMATCH = 0x2007
READ_ONLY = 0x2101
CANNOT_REGISTER = 0x2103
WRITE_FILE_MISSING = 0x2106
FILE_EXISTS = 0x2107
CANNOT_CHANGE = 0x2108
FILE_DEVICE_MISSING = 0x2301
