"""Which commands change the PLC: the table behind read-only clients (``read_only=True``).

One row per command code of manual 5-1-1: what the command changes in the PLC, or ``None``
for a command that only reads. The rows follow the manual: every command of its note 1
("not accepted ... if Write Protection from FINS Commands Sent to CPU Units via Networks is
selected": 0102, 0103, 0105, 0202, 0203, 0307, 0308, 0401, 0402, 0702, 0C01, 2101, 2103,
2141, 2203..2208, 220A..220C, 2215, 2301, 2302) changes the PLC, and so do

* 0C02/0C03 ACCESS RIGHT FORCED ACQUIRE / RELEASE: they take the access right from (or give
  it back for) another device such as a programming tool;
* 0920 MESSAGE CLEAR (its MESSAGE READ and FAL/FALS READ only read), 0620 CYCLE TIME READ with
  parameter 00 (it initializes the cycle time statistics), 2220 MEMORY CASSETTE TRANSFER except
  verify and data-type read: decided by the command's parameters;
* 2803..2805, the serial gateway: the encapsulated CompoWay/F or Modbus command may write to
  the device behind the port, which FINS cannot tell.

A command code not in the table (a raw frame of an unknown command) counts as changing the
PLC: a guard lets through only what it knows to be a read.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType

from .errors import ReadOnlyError

#: Command code → what the command changes in the PLC (``None``: nothing, it reads).
CHANGES: Mapping[int, str | None] = MappingProxyType(
    {
        0x0101: None,
        0x0102: "I/O memory",
        0x0103: "I/O memory",
        0x0104: None,
        0x0105: "I/O memory",
        0x0201: None,
        0x0202: "parameter areas",
        0x0203: "parameter areas",
        0x0306: None,
        0x0307: "the program",
        0x0308: "the program",
        0x0401: "the operating mode",
        0x0402: "the operating mode",
        0x0501: None,
        0x0502: None,
        0x0601: None,
        0x0620: "the cycle time statistics",  # parameter 00 only; 01 reads
        0x0701: None,
        0x0702: "the clock",
        0x0920: "the messages",  # MESSAGE CLEAR only; MESSAGE READ, FAL/FALS READ read
        0x0C01: "the access right",
        0x0C02: "the access right",
        0x0C03: "the access right",
        0x2101: "the errors",
        0x2102: None,
        0x2103: "the error log",
        0x2140: None,
        0x2141: "the FINS write access log",
        0x2201: None,
        0x2202: None,
        0x2203: "files",
        0x2204: "files",
        0x2205: "files",
        0x2207: "files",
        0x2208: "files",
        0x220A: "I/O memory or files",
        0x220B: "parameter areas or files",
        0x220C: "the program or files",
        0x2215: "files",
        0x2220: "the memory cassette or the CPU unit",  # verify and data-type read: none
        0x2301: "forced bits",
        0x2302: "forced bits",
        0x2803: "the device behind the serial gateway",
        0x2804: "the device behind the serial gateway",
        0x2805: "the device behind the serial gateway",
    }
)


def _message_read(params: bytes) -> bool:
    """0920: the kind in the first parameter byte's top bits; 01 is MESSAGE CLEAR."""
    return not params or params[0] >> 6 != 0b01


def _cycle_time_read(params: bytes) -> bool:
    """0620: parameter 01 reads, 00 initializes."""
    return params == b"\x01"


def _cassette_read(params: bytes) -> bool:
    """2220: disk (2 bytes), then operation 0002 (verify) or 8000 (read data type)."""
    return len(params) >= 4 and params[2:4] in (b"\x00\x02", b"\x80\x00")


#: Command codes whose parameters decide: a function saying whether they only read.
_READS_WHEN: Mapping[int, Callable[[bytes], bool]] = MappingProxyType(
    {0x0920: _message_read, 0x0620: _cycle_time_read, 0x2220: _cassette_read}
)


def changes(mrc: int, src: int, params: bytes) -> str | None:
    """What the command (MRC, SRC, parameter bytes) changes in the PLC; ``None``: nothing."""
    code = (mrc << 8) | src
    if code not in CHANGES:
        return "unknown: the command is not in the manual's table"
    reads = _READS_WHEN.get(code)
    if reads is not None and reads(params):
        return None
    return CHANGES[code]


def check_read_only(mrc: int, src: int, params: bytes, name: str = "") -> None:
    """Raise :class:`ReadOnlyError` if the command changes the PLC (``name``: its manual
    name, for the message)."""
    what = changes(mrc, src, params)
    if what is not None:
        label = f"{mrc:02X}{src:02X} {name}".rstrip()
        raise ReadOnlyError(
            f"read-only client: command {label} changes {what}; refused, nothing was sent "
            "(connect without read_only to allow it)",
            command_code=(mrc << 8) | src,
            changes=what,
        )


__all__ = ["CHANGES", "changes", "check_read_only"]
