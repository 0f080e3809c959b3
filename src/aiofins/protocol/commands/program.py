"""Program area (UM) access, 03 06 .. 03 08 (manual 5-3-10 .. 5-3-12).

The program number is always ``FFFF`` on CS/CJ/CP/NSJ CPU Units, so it is not a field: the
codec writes ``FFFF`` and a server answers ``1106`` (program missing) to anything else.
Addresses are byte offsets from the start of the program area and, like byte counts, must be
multiples of four. Bit 15 of the byte count flags the last data of the program area.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, ClassVar

from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError
from ._base import Request, _member, expect_no_data, finish

#: Bytes per 03 06 command (manual 5-3-10).
MAX_PROGRAM_READ_BYTES = 992
#: Bytes per 03 07 command (manual 5-3-11).
MAX_PROGRAM_WRITE_BYTES = 996
#: The only program number of CS/CJ/CP/NSJ CPU Units.
# manual wins: CV-series program number 0000 (wire-format notes) is refused with 1106.
PROGRAM_NUMBER = 0xFFFF

_LAST = 0x8000


# manual wins: the wire-format notes call clear code 10 unconfirmed; manual 5-3-12 lists it.
class ProgramClearCode(IntEnum):
    """Clear code of 03 08 (manual 5-3-12)."""

    WITHOUT_INTERRUPT_TASKS = 0x00
    WITH_INTERRUPT_TASKS = 0x10


# manual wins: the wire-format notes say the address must be even; 5-3-10 says a multiple of 4.
def _check_address(address: int) -> None:
    if not isinstance(address, int) or not 0 <= address <= 0xFFFFFFFF:
        raise CommandError(
            f"beginning address {address!r} out of range 0..0xFFFFFFFF", end_code=0x1103
        )
    if address % 4:
        raise CommandError(
            f"beginning address {address:08X} is not a multiple of 4", end_code=0x1102
        )


def _check_byte_count(count: int, high: int, end_code: int) -> None:
    if not 0 <= count <= high:
        raise CommandError(f"number of bytes {count} out of range 0..{high}", end_code=end_code)
    if count % 4:
        raise CommandError(f"number of bytes {count} is not a multiple of 4", end_code=0x1102)


def _read_program_number(r: Reader, name: str) -> None:
    number = r.u16()
    if number != PROGRAM_NUMBER:
        raise DecodeError(f"{name}: program number {number:04X} is not FFFF", end_code=0x1106)


def _read_head(r: Reader, name: str | None = None) -> tuple[int, int]:
    """Read what :func:`_head` writes; return the beginning address and number of bytes.

    With ``name`` (a command being decoded) the program number must be FFFF (else 1106); a
    response's echoed program number is not checked. Bit 15 of the number of bytes is kept.
    """
    if name is None:
        r.u16()
    else:
        _read_program_number(r, name)
    return r.u32(), r.u16()


def _check_echo(address: int, byte_count: int) -> None:
    """Range checks of a response's echoed beginning address and number of bytes."""
    if not isinstance(address, int) or not 0 <= address <= 0xFFFFFFFF:
        raise CommandError(f"beginning address {address!r} out of range 0..0xFFFFFFFF")
    if not isinstance(byte_count, int) or not 0 <= byte_count <= 0x7FFF:
        raise CommandError(f"number of bytes {byte_count!r} out of range 0..32767")


def _head(address: int, count: int, last: bool) -> bytes:
    return (
        PROGRAM_NUMBER.to_bytes(2, "big")
        + address.to_bytes(4, "big")
        + (count | (_LAST if last else 0)).to_bytes(2, "big")
    )


@dataclass(frozen=True, slots=True)
class ProgramAreaReadResult:
    """Data of 03 06: echoed beginning address, the bytes read, the last-data flag."""

    address: int
    data: bytes
    last: bool

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", bytes(self.data))
        _check_echo(self.address, len(self.data))

    def encode(self) -> bytes:
        return _head(self.address, len(self.data), self.last) + self.data


@dataclass(frozen=True)
class ProgramAreaRead(Request[ProgramAreaReadResult]):
    """03 06: read ``byte_count`` bytes of the program area from byte ``address``."""

    MRC: ClassVar[int] = 0x03
    SRC: ClassVar[int] = 0x06
    NAME: ClassVar[str] = "PROGRAM AREA READ"
    METHOD: ClassVar[str] = "program_area_read"
    IDEMPOTENT: ClassVar[bool] = True

    address: int
    byte_count: int

    def __post_init__(self) -> None:
        _check_address(self.address)
        if not isinstance(self.byte_count, int):
            raise CommandError(f"number of bytes must be an int, got {self.byte_count!r}")
        _check_byte_count(self.byte_count, MAX_PROGRAM_READ_BYTES, 0x110B)

    def encode(self) -> bytes:
        return _head(self.address, self.byte_count, False)

    @classmethod
    def decode(cls, params: bytes) -> ProgramAreaRead:
        r = Reader(params, cls.NAME)
        address, count = _read_head(r, cls.NAME)
        r.end()
        if count & _LAST:
            raise DecodeError(
                f"{cls.NAME}: bit 15 of the number of bytes must be 0", end_code=0x110C
            )
        with as_decode_error(cls.NAME):
            return cls(address, count)

    def decode_response(self, data: bytes) -> ProgramAreaReadResult:
        r = Reader(data, f"{self.NAME} response")
        address, count = _read_head(r)
        body = r.take(count & 0x7FFF)
        r.end()
        return ProgramAreaReadResult(address, body, bool(count & _LAST))


@dataclass(frozen=True, slots=True)
class ProgramAreaWriteResult:
    """Data of 03 07: the echoed beginning address, number of bytes and last-data flag."""

    address: int
    byte_count: int
    last: bool

    def __post_init__(self) -> None:
        _check_echo(self.address, self.byte_count)

    def encode(self) -> bytes:
        return _head(self.address, self.byte_count, self.last)


@dataclass(frozen=True)
class ProgramAreaWrite(Request[ProgramAreaWriteResult]):
    """03 07: write ``data`` to the program area from byte ``address``.

    ``last`` (bit 15 of the byte count) must be set on the block holding the program's last
    word. PROGRAM mode only.
    """

    MRC: ClassVar[int] = 0x03
    SRC: ClassVar[int] = 0x07
    NAME: ClassVar[str] = "PROGRAM AREA WRITE"
    METHOD: ClassVar[str] = "program_area_write"

    address: int
    data: bytes
    last: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.data, (bytes, bytearray, memoryview)):
            raise CommandError(f"data must be bytes, got {type(self.data).__name__}")
        object.__setattr__(self, "data", bytes(self.data))
        object.__setattr__(self, "last", bool(self.last))
        _check_address(self.address)
        _check_byte_count(len(self.data), MAX_PROGRAM_WRITE_BYTES, 0x1001)

    @property
    def byte_count(self) -> int:
        return len(self.data)

    def encode(self) -> bytes:
        return _head(self.address, len(self.data), self.last) + self.data

    @classmethod
    def decode(cls, params: bytes) -> ProgramAreaWrite:
        r = Reader(params, cls.NAME)
        address, count = _read_head(r, cls.NAME)
        data = r.rest()
        if len(data) != count & 0x7FFF:
            raise DecodeError(
                f"{cls.NAME}: number of bytes {count & 0x7FFF} but {len(data)} data bytes",
                end_code=0x1003,
            )
        with as_decode_error(cls.NAME):
            return cls(address, data, bool(count & _LAST))

    def decode_response(self, data: bytes) -> ProgramAreaWriteResult:
        r = Reader(data, f"{self.NAME} response")
        address, count = _read_head(r)
        r.end()
        return ProgramAreaWriteResult(address, count & 0x7FFF, bool(count & _LAST))


@dataclass(frozen=True)
class ProgramAreaClear(Request[None]):
    """03 08: clear the whole program area.

    ``clear_code`` is a :class:`ProgramClearCode` (plain ints are converted)."""

    MRC: ClassVar[int] = 0x03
    SRC: ClassVar[int] = 0x08
    NAME: ClassVar[str] = "PROGRAM AREA CLEAR"
    METHOD: ClassVar[str] = "program_area_clear"

    clear_code: int = ProgramClearCode.WITHOUT_INTERRUPT_TASKS

    def __post_init__(self) -> None:
        choices = "00 (without interrupt tasks), 10 (with interrupt tasks)"
        code = _member(ProgramClearCode, self.clear_code, "clear code", choices)
        object.__setattr__(self, "clear_code", code)

    def encode(self) -> bytes:
        return PROGRAM_NUMBER.to_bytes(2, "big") + bytes((self.clear_code,))

    @classmethod
    def decode(cls, params: bytes) -> ProgramAreaClear:
        r = Reader(params, cls.NAME)
        _read_program_number(r, cls.NAME)
        return finish(cls, r, r.u8())

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (
    ProgramAreaRead,
    ProgramAreaWrite,
    ProgramAreaClear,
)
