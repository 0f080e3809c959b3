"""Typed views of PLC words: integers, floats, BCD, bits and strings, with explicit word order.

FINS moves 16-bit words, each big-endian on the wire. Values wider than one word span several
consecutive words; Omron CPUs store them **least significant word first** (a DINT or REAL at
D100 keeps its low word in D100 and its high word in D101). Written as bytes of the value,
that is "CDAB" for 32 bits; we call it :attr:`WordOrder.LOW_FIRST` and make it the default.
Other devices and gateways use "ABCD" (:attr:`WordOrder.HIGH_FIRST`) or swap the bytes inside
each word ("BADC", "DCBA"); all four are available.

A :class:`ValueType` converts between Python values and a tuple of word values (0..0xFFFF)::

    >>> t = parse_value_type("float32")
    >>> t.encode(1.5)
    (0, 16320)
    >>> t.decode((0, 16320))
    1.5
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Literal

from .codec import from_bcd, to_bcd
from .errors import CommandError, DecodeError
from .inputs import float_value, shown
from .wordcodec import values_from_words, words_from_values


class WordOrder(Enum):
    """Order of the bytes of a multi-word value, named by the big-endian value bytes ABCD."""

    #: Omron's order: least significant word first, each word big-endian ("CDAB").
    LOW_FIRST = "CDAB"
    #: Most significant word first ("ABCD").
    HIGH_FIRST = "ABCD"
    #: Most significant word first, bytes swapped within each word ("BADC").
    HIGH_FIRST_SWAPPED = "BADC"
    #: Least significant word first, bytes swapped within each word ("DCBA").
    LOW_FIRST_SWAPPED = "DCBA"

    @classmethod
    def parse(cls, text: str | WordOrder) -> WordOrder:
        if isinstance(text, WordOrder):
            return text
        key = text.strip().upper()
        for order in cls:
            if key in (order.value, order.name):
                return order
        names = ", ".join(o.value for o in cls)
        raise CommandError(f"unknown word order {text!r}; use one of {names}")


def _words_from_bytes(raw: bytes, order: WordOrder) -> tuple[int, ...]:
    """Value bytes (big-endian, most significant first) → word values in memory order."""
    words = [raw[i : i + 2] for i in range(0, len(raw), 2)]
    if order in (WordOrder.LOW_FIRST, WordOrder.LOW_FIRST_SWAPPED):
        words.reverse()
    if order in (WordOrder.HIGH_FIRST_SWAPPED, WordOrder.LOW_FIRST_SWAPPED):
        words = [w[::-1] for w in words]
    return tuple((w[0] << 8) | w[1] for w in words)


def _bytes_from_words(words: Sequence[int], order: WordOrder) -> bytes:
    """Word values in memory order → value bytes, most significant first."""
    chunks = [bytes(((w >> 8) & 0xFF, w & 0xFF)) for w in words]
    if order in (WordOrder.HIGH_FIRST_SWAPPED, WordOrder.LOW_FIRST_SWAPPED):
        chunks = [c[::-1] for c in chunks]
    if order in (WordOrder.LOW_FIRST, WordOrder.LOW_FIRST_SWAPPED):
        chunks.reverse()
    return b"".join(chunks)


_NUMERIC: dict[str, tuple[str, int]] = {
    # name: (struct code, words)
    "int16": (">h", 1),
    "uint16": (">H", 1),
    "int32": (">i", 2),
    "uint32": (">I", 2),
    "int64": (">q", 4),
    "uint64": (">Q", 4),
    "float32": (">f", 2),
    "float64": (">d", 4),
}

#: Names accepted by :func:`parse_value_type` (strings take a length: ``string:10``).
TYPE_NAMES: tuple[str, ...] = (*_NUMERIC, "bcd16", "bcd32", "bit", "string")

_ALIASES = {
    "int": "int16",
    "word": "uint16",
    "uint": "uint16",
    "dint": "int32",
    "udint": "uint32",
    "lint": "int64",
    "ulint": "uint64",
    "real": "float32",
    "float": "float32",
    "lreal": "float64",
    "double": "float64",
    "bcd": "bcd16",
    "bcd4": "bcd16",
    "bcd8": "bcd32",
    "bool": "bit",
    "str": "string",
}

Value = int | float | str | bool

#: Type names whose values are floats, for the typed overloads of ``Client.read_value``
#: (``x: float = await plc.read_value("D100", "float32")`` type-checks).
FloatTypeName = Literal["float32", "float64", "real", "float", "lreal", "double", "REAL", "LREAL"]
#: Type names whose values are ints (BCD included).
IntTypeName = Literal[
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "bcd16",
    "bcd32",
    "int",
    "word",
    "uint",
    "dint",
    "udint",
    "lint",
    "ulint",
    "bcd",
    "bcd4",
    "bcd8",
    "INT",
    "UINT",
    "WORD",
    "DINT",
    "UDINT",
    "LINT",
    "ULINT",
]
#: Type names whose values are bools.
BoolTypeName = Literal["bit", "bool", "BOOL"]


@dataclass(frozen=True)
class ValueType:
    """A typed view of ``words`` consecutive words.

    ``kind`` is one of :data:`TYPE_NAMES`. For strings ``length`` is the size in bytes
    (rounded up to whole words), ``encoding`` the text encoding, ``swap_bytes`` stores the
    first character in the low byte of each word (Omron puts it in the high byte), and
    ``padding`` fills unused bytes on write and is stripped on read.
    """

    kind: str
    word_order: WordOrder = WordOrder.LOW_FIRST
    length: int = 0
    encoding: str = "ascii"
    swap_bytes: bool = False
    padding: bytes = b"\x00"

    def __post_init__(self) -> None:
        if self.kind not in TYPE_NAMES:
            raise CommandError(f"unknown value type {self.kind!r}; use one of {TYPE_NAMES}")
        if self.kind == "string":
            if not 1 <= self.length <= 1998:
                raise CommandError(f"string length must be 1..1998 bytes, got {self.length}")
            if len(self.padding) != 1:
                raise CommandError("string padding must be exactly one byte")

    @property
    def words(self) -> int:
        if self.kind in _NUMERIC:
            return _NUMERIC[self.kind][1]
        if self.kind == "bcd32":
            return 2
        if self.kind == "string":
            return (self.length + 1) // 2
        return 1

    @property
    def _string_order(self) -> WordOrder:
        """A string's bytes run first word first, the first character in the high byte of
        each word (the low byte with ``swap_bytes``)."""
        return WordOrder.HIGH_FIRST_SWAPPED if self.swap_bytes else WordOrder.HIGH_FIRST

    def __str__(self) -> str:
        if self.kind == "string":
            return f"string:{self.length}" + (":BADC" if self.swap_bytes else "")
        text = self.kind
        if self.words > 1 and self.kind != "string" and self.word_order != WordOrder.LOW_FIRST:
            text += f":{self.word_order.value}"
        return text

    # -- encoding -----------------------------------------------------------------------

    def encode(self, value: Value) -> tuple[int, ...]:
        """The word values that store ``value``; :class:`CommandError` if it does not fit."""
        kind = self.kind
        if kind in _NUMERIC:
            code, _ = _NUMERIC[kind]
            if isinstance(value, str):
                raise CommandError(f"{kind} needs a number, got {shown(value)}")
            if kind.startswith("float"):
                number: int | float = float_value("value", value, kind)
            else:
                if isinstance(value, float) and not value.is_integer():
                    raise CommandError(f"{kind} needs an integer, got {shown(value)}")
                number = int(value)
            try:
                raw = struct.pack(code, number)
            except OverflowError as exc:  # a finite float beyond float32's range
                raise CommandError(f"value {shown(value)} overflows {kind}") from exc
            except struct.error as exc:
                raise CommandError(f"{shown(value)} does not fit in {kind}") from exc
            return _words_from_bytes(raw, self.word_order)
        if kind in ("bcd16", "bcd32"):
            digits = 4 if kind == "bcd16" else 8
            if isinstance(value, (str, float)) or int(value) != value:
                raise CommandError(f"{kind} needs an integer, got {shown(value)}")
            n = int(value)
            if not 0 <= n < 10**digits:
                raise CommandError(
                    f"{shown(n)} does not fit in {digits} BCD digits (0..{10**digits - 1})"
                )
            raw = to_bcd(n, digits).to_bytes(digits // 2, "big")
            return _words_from_bytes(raw, self.word_order)
        if kind == "bit":
            if value not in (0, 1, True, False):
                raise CommandError(f"bit needs 0/1 or a bool, got {shown(value)}")
            return (int(value),)
        # string
        if not isinstance(value, str):
            raise CommandError(f"string needs a str, got {shown(value)}")
        try:
            raw = value.encode(self.encoding)
        except UnicodeEncodeError as exc:
            raise CommandError(f"{shown(value)} cannot be encoded as {self.encoding}") from exc
        if len(raw) > self.length:
            raise CommandError(f"{shown(value)} is {len(raw)} bytes, longer than {self.length}")
        return _words_from_bytes(raw.ljust(self.words * 2, self.padding), self._string_order)

    # -- decoding -----------------------------------------------------------------------

    def decode(self, words: Sequence[int]) -> Value:
        """The value stored in ``words`` (exactly :attr:`words` of them)."""
        if len(words) != self.words:
            raise DecodeError(f"{self} needs {self.words} word(s), got {len(words)}")
        for w in words:
            if not 0 <= w <= 0xFFFF:
                raise DecodeError(f"word value {w} out of range 0..65535")
        kind = self.kind
        if kind in _NUMERIC:
            code, _ = _NUMERIC[kind]
            value: Value = struct.unpack(code, _bytes_from_words(words, self.word_order))[0]
            return value
        if kind in ("bcd16", "bcd32"):
            raw = _bytes_from_words(words, self.word_order)
            return from_bcd(int.from_bytes(raw, "big"), len(raw) * 2)
        if kind == "bit":
            return bool(words[0] & 1)
        raw = _bytes_from_words(words, self._string_order)[: self.length]
        end = raw.find(b"\x00")
        if end >= 0:
            raw = raw[:end]
        raw = raw.rstrip(self.padding)
        try:
            return raw.decode(self.encoding)
        except UnicodeDecodeError as exc:
            raise DecodeError(f"words are not valid {self.encoding} text") from exc


_SPEC = re.compile(r"^\s*([A-Za-z]+[0-9]*)\s*(?::\s*([0-9]+))?\s*(?::\s*([A-Za-z]{4}))?\s*$")


def parse_value_type(
    spec: str | ValueType,
    word_order: WordOrder | str | None = None,
    *,
    default_word_order: WordOrder | str = WordOrder.LOW_FIRST,
) -> ValueType:
    """``"float32"``, ``"int32:ABCD"``, ``"string:16"``, ``"bcd8"``, ``"real"`` → a type.

    ``word_order`` overrides the order written in the spec; ``default_word_order`` applies
    when the spec names none (Omron's CDAB unless given). Strings take ABCD (the default:
    first character in the high byte) or BADC (``string:8:BADC``, in the low byte), honoured
    on read and write alike; other orders are refused for them.
    """
    if isinstance(spec, ValueType):
        return spec
    m = _SPEC.match(spec)
    if not m:
        raise CommandError(f"cannot read value type {spec!r}; e.g. float32, int32:ABCD, string:16")
    name = m.group(1).lower()
    name = _ALIASES.get(name, name)
    if m.group(2) and len(m.group(2)) > 5:  # no int() of thousands of digits
        raise CommandError(f"a length of {len(m.group(2))} digits in {spec[:40]!r}...: too long")
    length = int(m.group(2)) if m.group(2) else 0
    if name == "string" and not length:
        raise CommandError("a string type needs its length in bytes, e.g. string:16")
    if name != "string" and length:
        raise CommandError(f"{name} takes no length")
    given = word_order if word_order is not None else m.group(3)
    if name == "string":
        return ValueType(name, length=length, swap_bytes=_string_swap(given))
    order = WordOrder.parse(given) if given else WordOrder.parse(default_word_order)
    return ValueType(name, word_order=order, length=length)


def _string_swap(given: WordOrder | str | None) -> bool:
    """Whether a string's byte order (written ``string:N:ABCD`` or ``string:N:BADC``) swaps
    the bytes of each word. A string runs first word first: CDAB and DCBA, which reverse the
    words of a number, mean nothing for it and are refused (the client's default word order
    applies to numbers only)."""
    if not given:
        return False
    order = WordOrder.parse(given)
    if order is WordOrder.HIGH_FIRST:
        return False
    if order is WordOrder.HIGH_FIRST_SWAPPED:
        return True
    raise CommandError(
        f"a string's byte order is ABCD (first character in the high byte of each word, "
        f"Omron's) or BADC (in the low byte); got {order.value}"
    )


def words_to_values(vtype: ValueType, words: Sequence[int]) -> list[Value]:
    """Consecutive values of one type from a run of words (length a multiple of its size)."""
    n = vtype.words
    if len(words) % n:
        raise DecodeError(f"{len(words)} words is not a whole number of {vtype} values")
    fast = values_from_words(vtype, words)  # the whole run at once
    if fast is not None:
        return fast
    return [vtype.decode(words[i : i + n]) for i in range(0, len(words), n)]


def values_to_words(vtype: ValueType, values: Sequence[Value]) -> list[int]:
    """The words that store ``values`` one after another."""
    fast = words_from_values(vtype, values)  # the whole run at once
    if fast is not None:
        return fast
    out: list[int] = []
    for v in values:
        out.extend(vtype.encode(v))
    return out


__all__ = [
    "TYPE_NAMES",
    "BoolTypeName",
    "FloatTypeName",
    "IntTypeName",
    "Value",
    "ValueType",
    "WordOrder",
    "parse_value_type",
    "values_to_words",
    "words_to_values",
]
