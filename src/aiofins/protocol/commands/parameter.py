"""Parameter area access, 02 01 .. 02 03 (manual 5-3-7 .. 5-3-9).

A parameter area is addressed by a 2-byte code (leftmost byte always ``80``) and a word
offset from ``0000``. The number-of-words field carries a flag in bit 15: in a 02 01 response
it is set when the data includes the area's last word; in a 02 02 command it must be set when
the write includes the last word (otherwise the PLC writes nothing).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, ClassVar

from ..codec import Reader
from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError
from ._base import Request, expect_no_data

#: Words per 02 01 / 02 02 command (manual 5-3-7, 5-3-8).
MAX_PARAMETER_WORDS = 498

#: Bit 15 of a 02 01 / 02 02 word count: this block reaches the area's last word.
LAST_WORD = 0x8000


# manual wins: the CV-only codes 8001 and 8011 of the wire-format notes are not accepted.
class ParameterArea(IntEnum):
    """Parameter area codes of CS/CJ/CP/NSJ CPU Units (manual 5-3-7)."""

    ALL = 0x8000
    CPU_BUS_UNIT_SETUP = 0x8002
    PLC_SETUP = 0x8010
    IO_TABLE = 0x8012
    ROUTING_TABLES = 0x8013


#: Size in words of each parameter area (manual 5-3-7: 0000..01FF, 0000..04FF, ...).
PARAMETER_AREA_WORDS: dict[int, int] = {
    ParameterArea.ALL: 8000,
    ParameterArea.CPU_BUS_UNIT_SETUP: 5184,
    ParameterArea.PLC_SETUP: 512,
    ParameterArea.IO_TABLE: 1280,
    ParameterArea.ROUTING_TABLES: 512,
}

_CODES_TEXT = ", ".join(f"{code:04X}" for code in sorted(PARAMETER_AREA_WORDS))


def _area_words(area_code: int) -> int:
    """Size of the area; :class:`CommandError` (end code 1101) if the code is unknown."""
    try:
        return PARAMETER_AREA_WORDS[area_code]
    except (KeyError, TypeError):
        raise CommandError(
            f"parameter area code {area_code!r} not one of {_CODES_TEXT}", end_code=0x1101
        ) from None


def _check_span(area_code: int, begin_word: int, count: int, max_count: int) -> None:
    size = _area_words(area_code)
    if not isinstance(begin_word, int) or not 0 <= begin_word < size:
        raise CommandError(
            f"beginning word {begin_word!r} out of range 0..{size - 1} "
            f"of parameter area {area_code:04X}",
            end_code=0x1103,
        )
    if not isinstance(count, int) or not 0 <= count <= max_count:
        raise CommandError(
            f"number of words {count!r} out of range 0..{max_count}", end_code=0x1108
        )
    if begin_word + count > size:
        raise CommandError(
            f"words {begin_word}..{begin_word + count - 1} exceed parameter area "
            f"{area_code:04X} (words 0..{size - 1}): number of words out of range "
            f"0..{size - begin_word}",
            end_code=0x1104,
        )


def _check_words(words: tuple[int, ...]) -> None:
    for index, word in enumerate(words):
        if not isinstance(word, int) or not 0 <= word <= 0xFFFF:
            raise CommandError(f"word {index} value {word!r} out of range 0..65535")


def _words_bytes(words: tuple[int, ...]) -> bytes:
    return b"".join(word.to_bytes(2, "big") for word in words)


def _bytes_words(data: bytes) -> tuple[int, ...]:
    return tuple(int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2))


def _head(area_code: int, begin_word: int, count: int) -> bytes:
    """Parameter area code, beginning word, number of words: two bytes each."""
    return b"".join(v.to_bytes(2, "big") for v in (area_code, begin_word, count))


def _read_head(r: Reader) -> tuple[int, int, int]:
    """Read what :func:`_head` writes (the number of words keeps its bit 15)."""
    return r.u16(), r.u16(), r.u16()


def _block(area_code: int, begin_word: int, words: tuple[int, ...], last: bool | None) -> bytes:
    """The head with bit 15 of the number of words set for ``last``, then the words."""
    count = len(words) | (LAST_WORD if last else 0)
    return _head(area_code, begin_word, count) + _words_bytes(words)


@dataclass(frozen=True, slots=True)
class ParameterAreaReadResult:
    """Data of 02 01: echoed area code and beginning word, the words, the last-word flag."""

    area_code: int
    begin_word: int
    words: tuple[int, ...]
    last: bool

    def __post_init__(self) -> None:
        object.__setattr__(self, "words", tuple(self.words))
        for name, value in (("area code", self.area_code), ("beginning word", self.begin_word)):
            if not isinstance(value, int) or not 0 <= value <= 0xFFFF:
                raise CommandError(f"{name} {value!r} out of range 0..65535")
        if len(self.words) > 0x7FFF:
            raise CommandError(f"number of words {len(self.words)} out of range 0..32767")
        _check_words(self.words)

    def encode(self) -> bytes:
        return _block(self.area_code, self.begin_word, self.words, self.last)


@dataclass(frozen=True)
class ParameterAreaRead(Request[ParameterAreaReadResult]):
    """02 01: read ``count`` words of a parameter area from ``begin_word``."""

    MRC: ClassVar[int] = 0x02
    SRC: ClassVar[int] = 0x01
    NAME: ClassVar[str] = "PARAMETER AREA READ"
    METHOD: ClassVar[str] = "parameter_area_read"
    IDEMPOTENT: ClassVar[bool] = True

    area_code: int
    begin_word: int
    count: int

    def __post_init__(self) -> None:
        _check_span(self.area_code, self.begin_word, self.count, MAX_PARAMETER_WORDS)

    def encode(self) -> bytes:
        return _head(self.area_code, self.begin_word, self.count)

    @classmethod
    def decode(cls, params: bytes) -> ParameterAreaRead:
        r = Reader(params, cls.NAME)
        area_code, begin_word, count = _read_head(r)
        r.end()
        if count & LAST_WORD:
            raise DecodeError(
                f"{cls.NAME}: bit 15 of the number of words must be 0", end_code=0x110C
            )
        with as_decode_error(cls.NAME):
            return cls(area_code, begin_word, count)

    def decode_response(self, data: bytes) -> ParameterAreaReadResult:
        r = Reader(data, f"{self.NAME} response")
        area_code, begin_word, count = _read_head(r)
        words = _bytes_words(r.take(2 * (count & 0x7FFF)))
        r.end()
        return ParameterAreaReadResult(area_code, begin_word, words, bool(count & LAST_WORD))


@dataclass(frozen=True)
class ParameterAreaWrite(Request[None]):
    """02 02: write ``words`` to a parameter area from ``begin_word``.

    ``last`` is bit 15 of the number of words: it must be set when the write includes the
    area's last word. ``None`` (the default) sets it from the area size.
    """

    MRC: ClassVar[int] = 0x02
    SRC: ClassVar[int] = 0x02
    NAME: ClassVar[str] = "PARAMETER AREA WRITE"
    METHOD: ClassVar[str] = "parameter_area_write"

    area_code: int
    begin_word: int
    words: tuple[int, ...]
    last: bool | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "words", tuple(self.words))
        _check_span(self.area_code, self.begin_word, len(self.words), MAX_PARAMETER_WORDS)
        _check_words(self.words)
        if self.last is None:
            end = self.begin_word + len(self.words)
            object.__setattr__(self, "last", end == PARAMETER_AREA_WORDS[self.area_code])
        else:
            object.__setattr__(self, "last", bool(self.last))

    @property
    def count(self) -> int:
        return len(self.words)

    def encode(self) -> bytes:
        return _block(self.area_code, self.begin_word, self.words, self.last)

    @classmethod
    def decode(cls, params: bytes) -> ParameterAreaWrite:
        r = Reader(params, cls.NAME)
        area_code, begin_word, count = _read_head(r)
        data = r.rest()
        words = count & 0x7FFF
        if len(data) != 2 * words:
            raise DecodeError(
                f"{cls.NAME}: {words} words need {2 * words} data bytes, got {len(data)}",
                end_code=0x1003,
            )
        last = bool(count & LAST_WORD)
        with as_decode_error(cls.NAME):
            return cls(area_code, begin_word, _bytes_words(data), last)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


@dataclass(frozen=True)
class ParameterAreaClear(Request[None]):
    """02 03: write zeros to the first ``count`` words of a parameter area.

    The beginning word and the data word are always ``0000`` on the wire. ``count`` ``None``
    (the default) clears the whole area, as the manual requires.
    """

    MRC: ClassVar[int] = 0x02
    SRC: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "PARAMETER AREA CLEAR"
    METHOD: ClassVar[str] = "parameter_area_clear"

    area_code: int
    count: int | None = None

    def __post_init__(self) -> None:
        size = _area_words(self.area_code)
        count = size if self.count is None else self.count
        _check_span(self.area_code, 0, count, 0xFFFF)
        object.__setattr__(self, "count", count)

    def encode(self) -> bytes:
        count = self.count or 0
        return _head(self.area_code, 0, count) + b"\0\0"

    @classmethod
    def decode(cls, params: bytes) -> ParameterAreaClear:
        r = Reader(params, cls.NAME)
        area_code, begin_word, count = _read_head(r)
        data = r.u16()
        r.end()
        if begin_word != 0:
            raise DecodeError(
                f"{cls.NAME}: beginning word {begin_word:04X} must be 0000", end_code=0x1103
            )
        if data != 0:
            raise DecodeError(f"{cls.NAME}: data {data:04X} must be 0000", end_code=0x110C)
        with as_decode_error(cls.NAME):
            return cls(area_code, count)

    def decode_response(self, data: bytes) -> None:
        expect_no_data(self, data)


OPERATIONS: tuple[type[Request[Any]], ...] = (
    ParameterAreaRead,
    ParameterAreaWrite,
    ParameterAreaClear,
)
