"""Runs of words as :class:`array.array` s: typed values in bulk, without a Python object per
word or per value.

A FINS reply carries words big-endian. :meth:`Client.read_array` gives them as an
``array('H')``: unsigned 16-bit word values (``words[0]`` is the first word read), stored in
the **host's** byte order, like every ``array('H')``; its buffer is what
``numpy.frombuffer(words, dtype=numpy.uint16)`` views without a copy. :func:`words_to_array`
turns such a run into the values of one numeric type (``array('f')`` of ``float32``, ...) in
one of the four :class:`~aiofins.protocol.values.WordOrder` s, :func:`array_to_words` the
other way: a byte swap or two and one copy, whatever the length.

The trick is :mod:`~aiofins.protocol.wordcodec`'s: the memory words of a run of values,
stored in one byte order, are the values' bytes in another (CDAB words stored
little-endian are little-endian values, ABCD words stored big-endian big-endian values).
"""

from __future__ import annotations

import struct
import sys
from array import array
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from .errors import CommandError
from .values import ValueType, WordOrder, parse_value_type, values_to_words
from .wordcodec import NUMBER_CODES, _orders

__all__ = [
    "ARRAY_KINDS",
    "FloatArray",
    "NumberArray",
    "WordArray",
    "array_to_words",
    "array_type",
    "word_bytes",
    "words_to_array",
]

if TYPE_CHECKING:
    from typing import TypeAlias

    #: An ``array('H')`` of word values (``array[int]``).
    WordArray: TypeAlias = array[int]
    #: An ``array('f')`` or ``array('d')`` (``array[float]``).
    FloatArray: TypeAlias = array[float]
    #: An array of any numeric type code (``array[Any]``).
    NumberArray: TypeAlias = array[Any]
else:  # array is generic at run time from Python 3.12 only: hints stay evaluable before
    WordArray = FloatArray = NumberArray = array

#: The value kinds with an array form, and their ``array`` type codes.
ARRAY_KINDS = dict(NUMBER_CODES)
#: Words per element of each type code on this platform.
_WORDS = {code: array(code).itemsize // 2 for code in ARRAY_KINDS.values()}
#: The host's byte order as a ``struct`` prefix.
_NATIVE = "<" if sys.byteorder == "little" else ">"


def array_type(
    spec: str | ValueType, word_order: WordOrder | str = WordOrder.LOW_FIRST
) -> ValueType:
    """The value type of ``spec`` (``"float32"``, ``"int32:ABCD"``, a :class:`ValueType`),
    checked to have an array form: a fixed-size number (not BCD, a bit or a string)."""
    vtype = (
        spec
        if isinstance(spec, ValueType)
        else parse_value_type(spec, default_word_order=WordOrder.parse(word_order))
    )
    code = ARRAY_KINDS.get(vtype.kind)
    if code is not None and vtype.words == _WORDS[code]:
        return vtype
    if code is None:
        raise CommandError(
            f"{vtype.kind} values have no array form (arrays hold 16/32/64-bit integers and "
            "float32/float64): use read_values/write_values for them"
        )
    if array(code).itemsize != 2 * vtype.words:  # pragma: no cover - no such CPython platform
        raise CommandError(f"this platform's array({code!r}) is not {2 * vtype.words} bytes")
    return vtype


def _word_buffer(words: object) -> memoryview:
    """``words`` as a flat byte view of native unsigned 16-bit words (an ``array('H')``, a
    NumPy ``uint16`` array, any buffer of format ``H``), without a copy."""
    try:
        view = memoryview(words)  # type: ignore[arg-type]
    except TypeError:
        raise CommandError(
            f"words must be an array('H') (or a buffer of unsigned 16-bit words), got "
            f"{type(words).__name__}"
        ) from None
    if view.format not in ("H", "=H", _NATIVE + "H") or view.ndim != 1:
        raise CommandError(
            "words must be a one-dimensional buffer of unsigned 16-bit words in the host's byte "
            f"order (array('H'), numpy uint16), got format {view.format!r} with {view.ndim} "
            "dimensions"
        )
    if not view.c_contiguous:
        raise CommandError("words must be contiguous (a NumPy slice with a step: copy it first)")
    return view.cast("B")


def words_to_array(
    words: WordArray | memoryview | Any,
    spec: str | ValueType = "uint16",
    *,
    word_order: WordOrder | str = WordOrder.LOW_FIRST,
) -> NumberArray:
    """The values stored in a run of words, as an array of the type's code.

    ``words``: an ``array('H')`` as :meth:`Client.read_array` returns it, or any buffer of
    native unsigned 16-bit words (a NumPy ``uint16`` array). ``spec`` names a numeric type:
    ``int16`` (code ``h``), ``uint16`` (``H``), ``int32`` (``i``), ``uint32`` (``I``),
    ``int64`` (``q``), ``uint64`` (``Q``), ``float32`` (``f``), ``float64`` (``d``);
    multi-word values read in ``word_order`` (Omron's CDAB: least significant word first)
    unless the spec names one (``"float32:ABCD"``). The number of words must be a whole
    number of values. No Python object is made per word or value: one copy and at most two
    byte swaps.
    """
    vtype = array_type(spec, word_order)
    raw = _word_buffer(words)
    if len(raw) % (2 * vtype.words):
        raise CommandError(
            f"{len(raw) // 2} words are no whole number of {vtype.kind} values "
            f"({vtype.words} words each)"
        )
    words_order, value_order = _orders(vtype.word_order.value)
    if words_order != _NATIVE:
        swapped = array("H")
        swapped.frombytes(raw)
        swapped.byteswap()
        raw = memoryview(swapped).cast("B")
    out = array(ARRAY_KINDS[vtype.kind])
    out.frombytes(raw)
    if value_order != _NATIVE:
        out.byteswap()
    return out


def array_to_words(
    values: NumberArray | Sequence[int | float] | Any,
    spec: str | ValueType = "uint16",
    *,
    word_order: WordOrder | str = WordOrder.LOW_FIRST,
) -> WordArray:
    """The words storing ``values`` one after another, as an ``array('H')`` (host order).

    ``values``: an array of the type's code (or a buffer of it: a NumPy array of the same
    dtype), used as it is, or any sequence of numbers, converted in C. A value the type
    cannot hold raises :class:`CommandError` naming it, as :meth:`Client.write_values` does.
    """
    vtype = array_type(spec, word_order)
    code = ARRAY_KINDS[vtype.kind]
    typed = _typed(values, vtype, code)
    words_order, value_order = _orders(vtype.word_order.value)
    if value_order != _NATIVE:
        swapped = array(code)  # a copy to swap: the caller's array stays as it is
        swapped.frombytes(memoryview(typed).cast("B"))
        swapped.byteswap()
        typed = swapped
    out = array("H")
    out.frombytes(memoryview(typed).cast("B"))
    if words_order != _NATIVE:
        out.byteswap()
    return out


def _typed(values: object, vtype: ValueType, code: str) -> NumberArray:
    """``values`` as an array of ``code``: itself, a view of a buffer of that type, or the
    numbers converted (the per-value encoder names a value that does not fit)."""
    if isinstance(values, array) and values.typecode == code:
        return values
    if not isinstance(values, (array, list, tuple)):
        try:
            view = memoryview(values)  # type: ignore[arg-type]
        except TypeError:
            view = None
        if view is not None and view.format in (code, "=" + code, _NATIVE + code):
            if view.ndim != 1 or not view.c_contiguous:
                raise CommandError("values must be a one-dimensional contiguous buffer")
            out = array(code)
            out.frombytes(view.cast("B"))
            return out
    if not isinstance(values, Sequence) or isinstance(values, (str, bytes, bytearray)):
        raise CommandError(
            f"values must be an array('{code}'), a buffer of {vtype.kind} or a sequence of "
            f"numbers, got {type(values).__name__}"
        )
    numbers: Sequence[Any] = values
    try:
        if code == "f":  # array('f') would store 1e40 as inf: struct refuses it
            out = array(code)
            out.frombytes(struct.pack(f"={len(numbers)}f", *numbers))
            return out
        return array(code, numbers)
    except (TypeError, OverflowError, struct.error) as exc:
        values_to_words(vtype, list(numbers))  # names the value that does not fit
        raise CommandError(f"values are no {vtype.kind} values: {exc}") from None


def word_bytes(words: WordArray) -> bytes:
    """The words as FINS carries them (big-endian), e.g. a frame's data."""
    if _NATIVE == ">":
        return words.tobytes()
    swapped = array("H")
    swapped.frombytes(memoryview(words).cast("B"))
    swapped.byteswap()
    return swapped.tobytes()
