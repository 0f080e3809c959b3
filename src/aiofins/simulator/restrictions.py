"""Execution conditions of every command (manual 5-1-2, "FINS Command Restrictions") as data.

Each row says whether a command is refused in RUN / MONITOR / PROGRAM mode, while another node
holds the access right, under UM read protection, under DIP-switch UM write protection and
under network write protection. :func:`check_row` turns the PLC's state into the end code the
CPU Unit answers, or ``None`` when the command may run.

End codes: network write protection ``2102`` (manual 5-1-1 note 1); access right held by
another node ``3001``; UM read protection ``2002`` (read not possible: program area
protected); DIP-switch UM write protection ``2101`` (5-1-3: "protected using a switch
setting"); wrong mode ``2206`` in RUN, ``2205`` in MONITOR, ``2203`` in PROGRAM (5-1-3 "wrong
PLC mode" sub-codes naming the mode the PLC is in; the manual gives no per-command code).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..protocol.commands.access import (
    AccessRightAcquire,
    AccessRightForcedAcquire,
    AccessRightRelease,
)
from ..protocol.commands.clock import ClockRead, ClockWrite
from ..protocol.commands.debug import ForcedSetReset, ForcedSetResetCancel
from ..protocol.commands.errorlog import (
    ErrorClear,
    ErrorLogClear,
    ErrorLogRead,
    FinsWriteAccessLogClear,
    FinsWriteAccessLogRead,
)
from ..protocol.commands.file import (
    CreateDeleteDirectory,
    FileCopy,
    FileDelete,
    FileMemoryFormat,
    FileNameChange,
    FileNameRead,
    MemoryAreaFileTransfer,
    MemoryCassetteTransfer,
    ParameterAreaFileTransfer,
    ProgramAreaFileTransfer,
    SingleFileRead,
    SingleFileWrite,
)
from ..protocol.commands.gateway import (
    ConvertToCompowayFCommand,
    ConvertToModbusAsciiCommand,
    ConvertToModbusRtuCommand,
)
from ..protocol.commands.machine import ConnectionDataRead, CpuUnitDataRead
from ..protocol.commands.memory import (
    MemoryAreaFill,
    MemoryAreaRead,
    MemoryAreaTransfer,
    MemoryAreaWrite,
    MultipleMemoryAreaRead,
)
from ..protocol.commands.message import FalFalsRead, MessageClear, MessageRead
from ..protocol.commands.mode import Run, Stop
from ..protocol.commands.parameter import ParameterAreaClear, ParameterAreaRead, ParameterAreaWrite
from ..protocol.commands.program import ProgramAreaClear, ProgramAreaRead, ProgramAreaWrite
from ..protocol.commands.status import CpuUnitStatusRead, CycleTimeRead
from .codes import Operation
from .state import (
    ACCESS_RIGHT_HELD,
    NETWORK_WRITE_PROTECTED,
    UM_READ_PROTECTED,
    UM_WRITE_PROTECTED,
    WRONG_MODE_MONITOR,
    WRONG_MODE_PROGRAM,
    WRONG_MODE_RUN,
    Mode,
)

OK = True
NO = False

#: Wrong-mode end code per mode the PLC is in (the other refusals are named in state.py).
MODE_END_CODES: dict[Mode, int] = {
    Mode.RUN: WRONG_MODE_RUN,
    Mode.MONITOR: WRONG_MODE_MONITOR,
    Mode.PROGRAM: WRONG_MODE_PROGRAM,
}


@dataclass(frozen=True, slots=True)
class Restriction:
    """One row of 5-1-2: ``True`` = the command is accepted in that condition."""

    run: bool
    monitor: bool
    program: bool
    access_right: bool  # accepted while another node holds the access right
    um_read: bool  # accepted under UM read protection
    dip_write: bool  # accepted under DIP switch UM write protection
    network_write: bool  # accepted from a node refused by network write protection

    def allows_mode(self, mode: Mode) -> bool:
        return {Mode.RUN: self.run, Mode.MONITOR: self.monitor, Mode.PROGRAM: self.program}[mode]


def _r(*cols: bool) -> Restriction:
    return Restriction(*cols)


_READ = _r(OK, OK, OK, OK, OK, OK, OK)
_WRITE = _r(OK, OK, OK, OK, OK, OK, NO)  # I/O memory writes: only network protection
_CONTROL = _r(OK, OK, OK, NO, OK, OK, NO)  # access right + network protection
_PARAMETER_WRITE = _r(OK, OK, OK, NO, OK, NO, NO)
_PROGRAM_WRITE = _r(NO, NO, OK, NO, OK, NO, NO)
_DEBUG = _r(NO, OK, OK, OK, OK, OK, NO)

#: Operation (or ``(operation, variant)``) → restriction row, in the manual's order.
_ROWS: dict[Operation | tuple[Operation, str], Restriction] = {
    MemoryAreaRead: _READ,
    MemoryAreaWrite: _WRITE,
    MemoryAreaFill: _WRITE,
    MultipleMemoryAreaRead: _READ,
    MemoryAreaTransfer: _WRITE,
    ParameterAreaRead: _READ,
    ParameterAreaWrite: _PARAMETER_WRITE,
    ParameterAreaClear: _PARAMETER_WRITE,
    ProgramAreaRead: _r(OK, OK, OK, OK, NO, OK, OK),
    ProgramAreaWrite: _PROGRAM_WRITE,
    ProgramAreaClear: _PROGRAM_WRITE,
    Run: _CONTROL,
    Stop: _CONTROL,
    CpuUnitDataRead: _READ,
    ConnectionDataRead: _READ,
    CpuUnitStatusRead: _READ,
    CycleTimeRead: _r(OK, OK, NO, OK, OK, OK, OK),
    ClockRead: _READ,
    # manual wins: the 5-1-2 network-protection cell of 0702 is blank; 5-1-1 note 1 and the
    # command's own table (5-3-20) both refuse it.
    ClockWrite: _CONTROL,
    # 0920: only MESSAGE CLEAR is refused while another node holds the access right (5-1-2).
    # manual wins: 5-1-2 marks the whole row "Disabled" under network protection, but 5-1-1
    # note 1 does not list 0920 and the commands' own tables (5-3-21..23, CLEAR's included)
    # say OK: no variant is refused there (nor logged as a FINS write).
    (MessageRead, "read"): _READ,
    (MessageClear, "clear"): _r(OK, OK, OK, NO, OK, OK, OK),
    (FalFalsRead, "fal"): _READ,
    AccessRightAcquire: _CONTROL,
    AccessRightForcedAcquire: _READ,
    AccessRightRelease: _READ,
    ErrorClear: _CONTROL,
    ErrorLogRead: _READ,
    # manual wins: 5-1-2 says OK while another node holds the access right; the command's
    # own table (5-3-29) and both access-right lists (5-3-24, 5-3-25) refuse it.
    ErrorLogClear: _CONTROL,
    FinsWriteAccessLogRead: _READ,
    FinsWriteAccessLogClear: _CONTROL,
    FileNameRead: _READ,
    SingleFileRead: _READ,
    SingleFileWrite: _CONTROL,
    FileMemoryFormat: _CONTROL,
    FileDelete: _CONTROL,
    FileCopy: _CONTROL,
    FileNameChange: _CONTROL,
    MemoryAreaFileTransfer: _CONTROL,
    # Notes 1-3: file-to-area transfers are refused in RUN/MONITOR (and 220B under DIP
    # protection); of 220C only program-to-file transfers are allowed under DIP protection
    # (note 3; 5-3-41 note 1): a compare is refused, as the row's "Disabled" says.
    (ParameterAreaFileTransfer, "to_file"): _CONTROL,
    (ParameterAreaFileTransfer, "from_file"): _r(NO, NO, OK, NO, OK, NO, NO),
    (ParameterAreaFileTransfer, "compare"): _CONTROL,
    (ProgramAreaFileTransfer, "to_file"): _CONTROL,
    (ProgramAreaFileTransfer, "from_file"): _r(NO, NO, OK, NO, OK, NO, NO),
    (ProgramAreaFileTransfer, "compare"): _r(OK, OK, OK, NO, OK, NO, NO),
    CreateDeleteDirectory: _CONTROL,
    MemoryCassetteTransfer: _r(NO, NO, OK, NO, OK, OK, NO),
    ForcedSetReset: _DEBUG,
    ForcedSetResetCancel: _DEBUG,
    ConvertToCompowayFCommand: _READ,
    ConvertToModbusRtuCommand: _READ,
    ConvertToModbusAsciiCommand: _READ,
}

#: Command code (or ``(code, variant)``) → restriction row, in the manual's order.
RESTRICTIONS: dict[int | tuple[int, str], Restriction] = {
    (key[0].command_code(), key[1]) if isinstance(key, tuple) else key.command_code(): row
    for key, row in _ROWS.items()
}

_VARIANT_CODES = frozenset(k[0] for k in RESTRICTIONS if isinstance(k, tuple))
_MESSAGE = MessageRead.command_code()  # MessageClear and FalFalsRead share it
_AREA_FILE_TRANSFERS = frozenset(
    op.command_code() for op in (ParameterAreaFileTransfer, ProgramAreaFileTransfer)
)


def variant(command_code: int, params: bytes) -> str | None:
    """Which row of a command with several rows applies (0920, 220B, 220C)."""
    if command_code == _MESSAGE:
        top = (params[0] >> 6) if params else 0
        return {0: "read", 1: "clear"}.get(top, "fal")
    if command_code in _AREA_FILE_TRANSFERS:
        code = int.from_bytes(params[:2], "big") if len(params) >= 2 else 0
        return {0: "to_file", 1: "from_file"}.get(code, "compare")
    return None


def restriction_for(command_code: int, params: bytes = b"") -> Restriction | None:
    """The row for a command, or ``None`` for a code outside the table."""
    if command_code in _VARIANT_CODES:
        v = variant(command_code, params)
        return RESTRICTIONS.get((command_code, v or ""))
    return RESTRICTIONS.get(command_code)


def is_write_command(command_code: int, params: bytes = b"") -> bool:
    """A "FINS write command": one refused under network write protection (5-1-2 note 5)."""
    return is_write_row(restriction_for(command_code, params))


def is_write_row(row: Restriction | None) -> bool:
    """:func:`is_write_command` for a row already looked up."""
    return row is not None and not row.network_write


@dataclass(frozen=True, slots=True)
class Conditions:
    """The PLC state the restriction table is checked against for one command."""

    mode: Mode
    access_right_elsewhere: bool
    um_read_protected: bool
    um_write_protected: bool
    network_write_refused: bool


def check_row(row: Restriction | None, conditions: Conditions) -> int | None:
    """The end code refusing a command of ``row`` (from :func:`restriction_for`; ``None``: a
    code outside the table) under ``conditions``, or ``None`` if it may run."""
    if row is None:
        return None
    if conditions.network_write_refused and not row.network_write:
        return NETWORK_WRITE_PROTECTED
    if conditions.access_right_elsewhere and not row.access_right:
        return ACCESS_RIGHT_HELD
    if not row.allows_mode(conditions.mode):
        return MODE_END_CODES[conditions.mode]
    if conditions.um_read_protected and not row.um_read:
        return UM_READ_PROTECTED
    if conditions.um_write_protected and not row.dip_write:
        return UM_WRITE_PROTECTED
    return None
