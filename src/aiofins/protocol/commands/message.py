"""Message display (manual 5-3-21..5-3-23): 09 20 MESSAGE READ, MESSAGE CLEAR, FAL/FALS READ.

The three share one command code. Bits 15 and 14 of the two-byte parameter tell them apart:
00 read messages, 01 clear messages, 10 read a FAL/FALS message. For read and clear, bits
0-7 select MSG messages 0-7; for FAL/FALS read, bits 0-13 carry the FAL/FALS number.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from ..codec import Reader, ascii_field, check_range, pad_ascii
from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError
from ._base import Request, expect_no_data

_KIND_READ = 0b00
_KIND_CLEAR = 0b01
_KIND_FAL = 0b10

MESSAGE_SIZE = 32
FAL_MESSAGE_SIZE = 16
#: Largest FAL/FALS number bits 0-13 can carry (CS/CJ use 1-511).
MAX_FAL_NUMBER = 0x3FFF


def _kind(params: bytes) -> int:
    return params[0] >> 6 if params else _KIND_READ


def _mask_of(numbers: tuple[int, ...]) -> int:
    mask = 0
    for n in numbers:
        check_range("message number", n, 0, 7)
        mask |= 1 << n
    return mask


def _numbers_of(mask: int) -> tuple[int, ...]:
    return tuple(n for n in range(8) if mask >> n & 1)


def _read_mask_word(params: bytes, name: str, kind: int) -> int:
    r = Reader(params, name)
    word = r.u16()
    r.end()
    if word >> 14 != kind:
        raise DecodeError(f"{name}: parameter {word:04X} has the wrong bits 14/15", end_code=0x110C)
    if word & 0x3F00:
        raise DecodeError(f"{name}: parameter {word:04X} has bits 8-13 set", end_code=0x110C)
    return word & 0xFF


@dataclass(frozen=True, slots=True)
class Messages:
    """Response of MESSAGE READ: the returned message numbers (mask) and their texts."""

    #: Bit n ON: message n (0-7) is returned.
    mask: int
    #: One text per ON bit, in ascending message number order.
    texts: tuple[str, ...]

    def __post_init__(self) -> None:
        check_range("message mask", self.mask, 0, 0xFF)
        object.__setattr__(self, "texts", tuple(self.texts))
        if len(self.texts) != bin(self.mask).count("1"):
            raise CommandError(
                f"message mask {self.mask:02X} selects {bin(self.mask).count('1')} message(s), "
                f"got {len(self.texts)} text(s)"
            )

    @property
    def numbers(self) -> tuple[int, ...]:
        return _numbers_of(self.mask)

    def by_number(self) -> dict[int, str]:
        """Message number → text."""
        return dict(zip(self.numbers, self.texts, strict=True))

    def encode(self) -> bytes:
        return self.mask.to_bytes(2, "big") + b"".join(
            pad_ascii(t, MESSAGE_SIZE, "message") for t in self.texts
        )

    @classmethod
    def decode(cls, data: bytes) -> Messages:
        r = Reader(data, "MESSAGE READ response")
        word = r.u16()
        if word & 0xFF00:
            raise DecodeError(f"MESSAGE READ response: message number word {word:04X} invalid")
        texts = tuple(ascii_field(r.take(MESSAGE_SIZE)) for _ in _numbers_of(word))
        r.end()
        return cls(word, texts)


@dataclass(frozen=True)
class MessageRead(Request[Messages]):
    """09 20 MESSAGE READ (bits 15/14 = 00): read MSG messages selected by ``mask``."""

    MRC: ClassVar[int] = 0x09
    SRC: ClassVar[int] = 0x20
    NAME: ClassVar[str] = "MESSAGE READ"
    METHOD: ClassVar[str] = "message_read"
    IDEMPOTENT: ClassVar[bool] = True

    #: Bit n ON selects message n (0-7). Default: all eight.
    mask: int = 0xFF

    def __post_init__(self) -> None:
        check_range("message mask", self.mask, 0, 0xFF)

    @classmethod
    def of(cls, *numbers: int) -> MessageRead:
        """Read the given message numbers (0-7)."""
        return cls(_mask_of(numbers))

    @classmethod
    def matches(cls, params: bytes) -> bool:
        return _kind(params) == _KIND_READ

    def encode(self) -> bytes:
        return self.mask.to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> MessageRead:
        return cls(_read_mask_word(params, cls.NAME, _KIND_READ))

    def decode_response(self, data: bytes) -> Messages:
        return Messages.decode(data)


@dataclass(frozen=True)
class MessageClear(Request[None]):
    """09 20 MESSAGE CLEAR (bits 15/14 = 01): clear the MSG messages selected by ``mask``."""

    MRC: ClassVar[int] = 0x09
    SRC: ClassVar[int] = 0x20
    NAME: ClassVar[str] = "MESSAGE CLEAR"
    METHOD: ClassVar[str] = "message_clear"

    #: Bit n ON clears message n (0-7); no default, clearing is explicit.
    mask: int

    def __post_init__(self) -> None:
        check_range("message mask", self.mask, 0, 0xFF)

    @classmethod
    def of(cls, *numbers: int) -> MessageClear:
        """Clear the given message numbers (0-7)."""
        return cls(_mask_of(numbers))

    @classmethod
    def matches(cls, params: bytes) -> bool:
        return bool(params) and _kind(params) == _KIND_CLEAR

    def encode(self) -> bytes:
        return (_KIND_CLEAR << 14 | self.mask).to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> MessageClear:
        return cls(_read_mask_word(params, cls.NAME, _KIND_CLEAR))

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True, slots=True)
class FalFalsMessage:
    """Response of FAL/FALS READ: the FAL/FALS number and its 16-character message."""

    number: int
    message: str

    def __post_init__(self) -> None:
        check_range("FAL/FALS number", self.number, 0, MAX_FAL_NUMBER)

    def encode(self) -> bytes:
        # The response echoes the command's parameter word (bit 15 ON).
        word = _KIND_FAL << 14 | self.number
        return word.to_bytes(2, "big") + pad_ascii(self.message, FAL_MESSAGE_SIZE, "FAL message")

    @classmethod
    def decode(cls, data: bytes) -> FalFalsMessage:
        r = Reader(data, "FAL/FALS READ response")
        word = r.u16()
        message = ascii_field(r.take(FAL_MESSAGE_SIZE))
        r.end()
        return cls(word & MAX_FAL_NUMBER, message)


@dataclass(frozen=True)
class FalFalsRead(Request[FalFalsMessage]):
    """09 20 FAL/FALS READ (bits 15/14 = 10): the message of FAL/FALS ``number``."""

    MRC: ClassVar[int] = 0x09
    SRC: ClassVar[int] = 0x20
    NAME: ClassVar[str] = "FAL/FALS READ"
    METHOD: ClassVar[str] = "fal_fals_read"
    IDEMPOTENT: ClassVar[bool] = True

    number: int

    def __post_init__(self) -> None:
        check_range("FAL/FALS number", self.number, 0, MAX_FAL_NUMBER)

    @classmethod
    def matches(cls, params: bytes) -> bool:
        return bool(params) and _kind(params) == _KIND_FAL

    def encode(self) -> bytes:
        return (_KIND_FAL << 14 | self.number).to_bytes(2, "big")

    @classmethod
    def decode(cls, params: bytes) -> FalFalsRead:
        r = Reader(params, cls.NAME)
        word = r.u16()
        r.end()
        if word >> 14 != _KIND_FAL:
            raise DecodeError(f"{cls.NAME}: parameter {word:04X} lacks bit 15", end_code=0x110C)
        with as_decode_error(None):
            return cls(word & MAX_FAL_NUMBER)

    def decode_response(self, data: bytes) -> FalFalsMessage:
        return FalFalsMessage.decode(data)


OPERATIONS: tuple[type[Request[Any]], ...] = (MessageRead, MessageClear, FalFalsRead)
