"""Whole-run codecs: element data <-> integers, and words <-> typed values, one ``struct``
call per run instead of one conversion per element.

FINS carries elements big-endian: bits as one byte ``00``/``01``, words as two bytes,
words with forced status as four. A typed value of ``n`` words in one of the four
:class:`~aiofins.protocol.values.WordOrder` s is the same as a run of words packed in one
byte order and read back as the value in another (see :func:`_orders`), so a run of values
of one type converts with two ``struct`` calls.

Each function here returns ``None`` where the input holds something the fast path does not
take (a word out of range, a value of the wrong type, a BCD nibble over 9): the caller then
runs its per-element definition, which says exactly what is wrong. The fast and the per-element
paths give the same results (``tests/protocol/test_wordcodec.py`` checks them against each
other).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .values import Value, ValueType

__all__ = [
    "NUMBER_CODES",
    "numeric_codec",
    "pack_elements",
    "unpack_elements",
    "values_from_words",
    "words_from_values",
]

#: ``struct`` codes of unsigned elements by size in bytes.
_ELEMENT_CODES = {1: "B", 2: "H", 4: "I"}
#: ``struct`` codes of the numeric value kinds.
NUMBER_CODES = {
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float32": "f",
    "float64": "d",
}
_BCD_CODES = {"bcd16": "H", "bcd32": "I"}


@lru_cache(maxsize=256)
def _struct(fmt: str) -> struct.Struct:
    return struct.Struct(fmt)


def unpack_elements(data: bytes, size: int) -> tuple[int, ...]:
    """Elements of ``size`` bytes (1, 2 or 4), big-endian, as unsigned integers.

    ``len(data)`` must be a multiple of ``size`` (the callers check it).
    """
    if size == 1:
        return tuple(data)
    return _struct(f">{len(data) // size}{_ELEMENT_CODES[size]}").unpack(data)


def pack_elements(values: Sequence[int], size: int) -> bytes | None:
    """Unsigned integers as big-endian elements of ``size`` bytes; ``None`` if one is not an
    ``int`` in range (the caller's per-element path names it)."""
    try:
        if size == 1:
            if not all(type(v) is int for v in values):
                return None
            return bytes(values)  # ValueError outside 0..255
        if not all(type(v) is int for v in values):
            return None
        return _struct(f">{len(values)}{_ELEMENT_CODES[size]}").pack(*values)
    except (struct.error, ValueError, KeyError):
        return None


@lru_cache(maxsize=64)
def _orders(order_value: str) -> tuple[str, str]:
    """(byte order to pack memory words in, byte order to read the value in) for a word order.

    Memory words ``w0 w1 ...``: ABCD (high word first, each word big-endian) is the value's
    bytes as they are; CDAB (low word first) packed little-endian is the value's bytes
    reversed, a little-endian value; BADC packed little-endian and DCBA packed big-endian
    give ABCD and the reversed bytes likewise. One-word values follow the same rule.
    """
    return {
        "ABCD": (">", ">"),
        "CDAB": ("<", "<"),
        "BADC": ("<", ">"),
        "DCBA": (">", "<"),
    }[order_value]


def numeric_codec(vtype: ValueType, count: int) -> tuple[struct.Struct, struct.Struct] | None:
    """(memory words struct, values struct) for ``count`` values of a numeric or BCD type
    (the BCD values as the integers of their digits' nibbles), else ``None``.

    ``values.unpack(words.pack(*memory_words))`` decodes a run; ``words.unpack(values.pack(
    *numbers))`` encodes one.
    """
    return _run_codec(vtype, count)


@lru_cache(maxsize=512)
def _run_codec(vtype: ValueType, count: int) -> tuple[struct.Struct, struct.Struct] | None:
    code = NUMBER_CODES.get(vtype.kind) or _BCD_CODES.get(vtype.kind)
    if code is None:
        return None
    words_order, value_order = _orders(vtype.word_order.value)
    return (
        _struct(f"{words_order}{count * vtype.words}H"),
        _struct(f"{value_order}{count}{code}"),
    )


def values_from_words(vtype: ValueType, words: Sequence[int]) -> list[Value] | None:
    """The values of a run of words (a whole number of values), or ``None`` to say: decode
    them one by one (strings; or a word out of range, an invalid BCD digit: the per-value
    decode raises the error naming it)."""
    kind = vtype.kind
    if kind == "bit":
        try:
            return [bool(w & 1) for w in words] if all(0 <= w <= 0xFFFF for w in words) else None
        except TypeError:
            return None
    n = vtype.words
    codec = _run_codec(vtype, len(words) // n)
    if codec is None:
        return None
    pack_words, values = codec
    try:
        raw = pack_words.pack(*words)
    except struct.error:
        return None
    out: list[Value] = list(values.unpack(raw))
    if kind in _BCD_CODES:
        digits = 4 * n
        texts = [f"{v:0{digits}x}" for v in out]
        if not "".join(texts).isdigit():
            return None
        out = [int(t) for t in texts]
    return out


def words_from_values(vtype: ValueType, values: Sequence[Value]) -> list[int] | None:
    """The words storing ``values`` one after another, or ``None`` to say: encode them one
    by one (strings; or a value that is not of the type or does not fit: the per-value encode
    raises the error naming it)."""
    kind = vtype.kind
    if kind == "bit":
        if all(type(v) is bool or (type(v) is int and 0 <= v <= 1) for v in values):
            return [int(v) for v in values]
        return None
    codec = _run_codec(vtype, len(values))
    if codec is None:
        return None
    pack_words, pack_values = codec
    numbers: list[int | float]
    if kind.startswith("float"):
        if not all(type(v) is float or type(v) is int for v in values):
            return None
        numbers = list(values)  # type: ignore[arg-type]
    else:
        if not all(type(v) is int for v in values):
            return None
        numbers = list(values)  # type: ignore[arg-type]
        if kind in _BCD_CODES:
            digits = 4 * vtype.words
            if not all(0 <= v < 10**digits for v in numbers):
                return None
            numbers = [int(str(v), 16) for v in numbers]
    try:
        raw = pack_values.pack(*numbers)
    except (struct.error, OverflowError):
        return None
    return list(pack_words.unpack(raw))
