"""Arrays of typed values against the per-value codecs (words_to_values / values_to_words)."""

from __future__ import annotations

import math
import struct
import sys
from array import array

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.arrays import (
    ARRAY_KINDS,
    array_to_words,
    array_type,
    word_bytes,
    words_to_array,
)
from aiofins.protocol.errors import CommandError
from aiofins.protocol.values import ValueType, WordOrder, values_to_words, words_to_values

ORDERS = list(WordOrder)
KINDS = sorted(ARRAY_KINDS)
WORDS = st.integers(0, 0xFFFF)


def same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


@given(
    kind=st.sampled_from(KINDS),
    order=st.sampled_from(ORDERS),
    data=st.data(),
)
def test_words_to_array_agrees_with_the_per_value_decode(
    kind: str, order: WordOrder, data: st.DataObject
) -> None:
    vtype = ValueType(kind, order)
    n = data.draw(st.integers(0, 40))
    words = data.draw(st.lists(WORDS, min_size=n * vtype.words, max_size=n * vtype.words))
    got = words_to_array(array("H", words), vtype)
    assert got.typecode == ARRAY_KINDS[kind]
    expected = words_to_values(vtype, words)
    assert len(got) == len(expected)
    if kind.startswith("float"):
        assert all(same(a, float(b)) for a, b in zip(got, expected, strict=True))
    else:
        assert got.tolist() == expected
    # and back: the same words (a NaN keeps its bits through the array)
    assert array_to_words(got, vtype).tolist() == words


@given(
    kind=st.sampled_from([k for k in KINDS if not k.startswith("float")]),
    order=st.sampled_from(ORDERS),
    data=st.data(),
)
def test_integers_to_words_agree_with_the_per_value_encode(
    kind: str, order: WordOrder, data: st.DataObject
) -> None:
    vtype = ValueType(kind, order)
    bits = 16 * vtype.words
    signed = kind[0] == "i"
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    values = data.draw(st.lists(st.integers(low, high), max_size=30))
    words = array_to_words(values, vtype)
    assert words.typecode == "H"
    assert words.tolist() == values_to_words(vtype, values)
    assert words_to_array(words, vtype).tolist() == values


@given(
    order=st.sampled_from(ORDERS),
    values=st.lists(st.floats(width=32, allow_nan=False), max_size=30),
)
def test_float32_to_words_agree_with_the_per_value_encode(
    order: WordOrder, values: list[float]
) -> None:
    vtype = ValueType("float32", order)
    words = array_to_words(values, vtype)
    assert words.tolist() == values_to_words(vtype, values)
    assert words_to_array(words, vtype).tolist() == values


def test_words_in_the_documented_orders() -> None:
    """-2.5 is 0xC0200000: CDAB stores the low word 0x0000 first, ABCD the high one."""
    assert array_to_words([-2.5], "float32").tolist() == [0x0000, 0xC020]
    assert array_to_words([-2.5], "float32:ABCD").tolist() == [0xC020, 0x0000]
    assert array_to_words([-2.5], "float32:BADC").tolist() == [0x20C0, 0x0000]
    assert array_to_words([-2.5], "float32:DCBA").tolist() == [0x0000, 0x20C0]
    assert array_to_words([-2.5], "float32", word_order="ABCD").tolist() == [0xC020, 0x0000]
    assert words_to_array(array("H", [0x5678, 0x1234]), "uint32").tolist() == [0x12345678]
    assert words_to_array(array("H", [0x1234, 0x5678]), "int32:ABCD").tolist() == [0x12345678]
    assert words_to_array(array("H", [0xFFFF]), "int16").tolist() == [-1]


def test_an_array_holds_host_order_words_and_word_bytes_gives_the_wire_bytes() -> None:
    words = array("H", [0x1234, 0xABCD])
    assert word_bytes(words) == b"\x12\x34\xab\xcd"  # as FINS carries them
    assert words.tobytes() == struct.pack("=2H", 0x1234, 0xABCD)  # the host's order
    assert words.tolist() == [0x1234, 0xABCD]  # word_bytes left the array as it was
    if sys.byteorder == "little":
        assert words.tobytes() == b"\x34\x12\xcd\xab"


def test_a_caller_array_is_not_changed() -> None:
    values = array("f", [1.5, -2.0])
    array_to_words(values, "float32:ABCD")  # needs swapping: done in a copy
    assert values.tolist() == [1.5, -2.0]
    words = array("H", [1, 2, 3, 4])
    words_to_array(words, "int32:ABCD")
    assert words.tolist() == [1, 2, 3, 4]


def test_numpy_views_without_a_copy_and_buffers_are_taken() -> None:
    numpy = pytest.importorskip("numpy")
    words = array("H", [1, 2, 0xFFFF])
    view = numpy.frombuffer(words, dtype=numpy.uint16)
    assert view.tolist() == [1, 2, 0xFFFF]
    words[0] = 7  # the same memory: no copy was made
    assert int(view[0]) == 7
    assert words_to_array(numpy.array([0, 0xC020], dtype=numpy.uint16), "float32").tolist() == [
        -2.5
    ]
    floats = numpy.array([-2.5, 1.0], dtype=numpy.float32)
    assert array_to_words(floats, "float32").tolist() == [0, 0xC020, 0, 0x3F80]
    with pytest.raises(CommandError, match="format '>H'"):
        words_to_array(numpy.array([1], dtype=">u2"), "uint16")
    with pytest.raises(CommandError, match="contiguous"):
        words_to_array(numpy.arange(8, dtype=numpy.uint16)[::2], "uint16")


def test_what_has_no_array_form_or_does_not_fit_is_refused() -> None:
    for spec in ("bcd16", "bit", "string:4"):
        with pytest.raises(CommandError, match="no array form"):
            array_type(spec)
    with pytest.raises(CommandError, match="no whole number of int32"):
        words_to_array(array("H", [1, 2, 3]), "int32")
    with pytest.raises(CommandError, match="unsigned 16-bit words"):
        words_to_array(array("i", [1]), "uint16")
    with pytest.raises(CommandError, match="unsigned 16-bit"):
        words_to_array([1, 2], "uint16")
    with pytest.raises(CommandError, match="70000"):
        array_to_words([70000], "int16")
    with pytest.raises(CommandError, match="1e"):
        array_to_words([1e40], "float32")  # array('f') alone would store inf
    with pytest.raises(CommandError, match="sequence of numbers"):
        array_to_words("12", "uint16")
