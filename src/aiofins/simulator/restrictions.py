"""Execution conditions of every command (manual 5-1-2, "FINS Command Restrictions") as data.

Each row says whether a command is refused in RUN / MONITOR / PROGRAM mode, while another node
holds the access right, under UM read protection, under DIP-switch UM write protection and
under network write protection. :func:`check` turns the PLC's state into the end code the CPU
Unit answers, or ``None`` when the command may run.

End codes: network write protection ``2102`` (manual 5-1-1 note 1); access right held by
another node ``3001``; UM read protection ``2002`` (read not possible: program area
protected); DIP-switch UM write protection ``2101`` (5-1-3: "protected using a switch
setting"); wrong mode ``2206`` in RUN, ``2205`` in MONITOR, ``2203`` in PROGRAM (5-1-3 "wrong
PLC mode" sub-codes naming the mode the PLC is in; the manual gives no per-command code).
"""

from __future__ import annotations

from dataclasses import dataclass

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

#: Command code (or ``(code, variant)``) → restriction row, in the manual's order.
RESTRICTIONS: dict[int | tuple[int, str], Restriction] = {
    0x0101: _READ,
    0x0102: _WRITE,
    0x0103: _WRITE,
    0x0104: _READ,
    0x0105: _WRITE,
    0x0201: _READ,
    0x0202: _PARAMETER_WRITE,
    0x0203: _PARAMETER_WRITE,
    0x0306: _r(OK, OK, OK, OK, NO, OK, OK),
    0x0307: _PROGRAM_WRITE,
    0x0308: _PROGRAM_WRITE,
    0x0401: _CONTROL,
    0x0402: _CONTROL,
    0x0501: _READ,
    0x0502: _READ,
    0x0601: _READ,
    0x0620: _r(OK, OK, NO, OK, OK, OK, OK),
    0x0701: _READ,
    # manual wins: the 5-1-2 network-protection cell of 0702 is blank; 5-1-1 note 1 and the
    # command's own table (5-3-20) both refuse it.
    0x0702: _CONTROL,
    # 0920: only MESSAGE CLEAR is refused while another node holds the access right (5-1-2).
    # manual wins: 5-1-2 marks the whole row "Disabled" under network protection, but 5-1-1
    # note 1 does not list 0920 and 5-3-21..23 say OK; only CLEAR writes, so only it is refused.
    (0x0920, "read"): _READ,
    (0x0920, "clear"): _CONTROL,
    (0x0920, "fal"): _READ,
    0x0C01: _CONTROL,
    0x0C02: _READ,
    0x0C03: _READ,
    0x2101: _CONTROL,
    0x2102: _READ,
    0x2103: _r(OK, OK, OK, OK, OK, OK, NO),
    0x2140: _READ,
    0x2141: _CONTROL,
    0x2201: _READ,
    0x2202: _READ,
    0x2203: _CONTROL,
    0x2204: _CONTROL,
    0x2205: _CONTROL,
    0x2207: _CONTROL,
    0x2208: _CONTROL,
    0x220A: _CONTROL,
    # Notes 1-3: file-to-area transfers are refused in RUN/MONITOR (and 220B under DIP
    # protection); 220C program-to-file transfers are allowed under DIP protection.
    (0x220B, "to_file"): _CONTROL,
    (0x220B, "from_file"): _r(NO, NO, OK, NO, OK, NO, NO),
    (0x220B, "compare"): _CONTROL,
    (0x220C, "to_file"): _CONTROL,
    (0x220C, "from_file"): _r(NO, NO, OK, NO, OK, NO, NO),
    (0x220C, "compare"): _CONTROL,
    0x2215: _CONTROL,
    0x2220: _r(NO, NO, OK, NO, OK, OK, NO),
    0x2301: _DEBUG,
    0x2302: _DEBUG,
    0x2803: _READ,
    0x2804: _READ,
    0x2805: _READ,
}

_VARIANT_CODES = frozenset(k[0] for k in RESTRICTIONS if isinstance(k, tuple))


def variant(command_code: int, params: bytes) -> str | None:
    """Which row of a command with several rows applies (0920, 220B, 220C)."""
    if command_code == 0x0920:
        top = (params[0] >> 6) if params else 0
        return {0: "read", 1: "clear"}.get(top, "fal")
    if command_code in (0x220B, 0x220C):
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


def check(command_code: int, params: bytes, conditions: Conditions) -> int | None:
    """The end code refusing the command under ``conditions``, or ``None`` if it may run."""
    return check_row(restriction_for(command_code, params), conditions)


def check_row(row: Restriction | None, conditions: Conditions) -> int | None:
    """:func:`check` for a row already looked up (``None``: a code outside the table)."""
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
