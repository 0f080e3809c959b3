"""Typed values: exact word layouts and hypothesis round trips for every type and word order."""

from __future__ import annotations

import contextlib
import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.errors import CommandError, DecodeError
from aiofins.protocol.values import (
    ValueType,
    WordOrder,
    parse_value_type,
    values_to_words,
    words_to_values,
)


def test_float32_is_low_word_first_by_default() -> None:
    # 1.5f == 0x3FC00000: Omron keeps the low word 0x0000 in the first word.
    assert parse_value_type("float32").encode(1.5) == (0x0000, 0x3FC0)
    assert parse_value_type("float32:ABCD").encode(1.5) == (0x3FC0, 0x0000)
    assert parse_value_type("real").decode((0x0000, 0x3FC0)) == 1.5


@pytest.mark.parametrize(
    ("order", "words"),
    [
        ("CDAB", (0x5678, 0x1234)),
        ("ABCD", (0x1234, 0x5678)),
        ("BADC", (0x3412, 0x7856)),
        ("DCBA", (0x7856, 0x3412)),
    ],
)
def test_uint32_in_every_word_order(order: str, words: tuple[int, int]) -> None:
    vtype = parse_value_type("uint32", word_order=order)
    assert vtype.encode(0x12345678) == words
    assert vtype.decode(words) == 0x12345678


def test_int64_and_float64_span_four_words_low_first() -> None:
    assert parse_value_type("uint64").encode(0x1122334455667788) == (0x7788, 0x5566, 0x3344, 0x1122)
    raw = struct.pack(">d", -2.25)
    expected = tuple(int.from_bytes(raw[i : i + 2], "big") for i in (6, 4, 2, 0))
    assert parse_value_type("lreal").encode(-2.25) == expected


def test_int16_negative_and_bcd() -> None:
    assert parse_value_type("int16").encode(-1) == (0xFFFF,)
    assert parse_value_type("bcd16").encode(1234) == (0x1234,)
    assert parse_value_type("bcd8").encode(12345678) == (0x5678, 0x1234)
    assert parse_value_type("bcd32").decode((0x5678, 0x1234)) == 12345678


def test_string_layout_first_char_in_high_byte() -> None:
    vtype = parse_value_type("string:5")
    assert vtype.words == 3
    assert vtype.encode("ABC") == (0x4142, 0x4300, 0x0000)
    assert vtype.decode((0x4142, 0x4300, 0x0000)) == "ABC"
    swapped = ValueType("string", length=4, swap_bytes=True, padding=b" ")
    assert swapped.encode("AB") == (0x4241, 0x2020)
    assert swapped.decode((0x4241, 0x2020)) == "AB"


@pytest.mark.parametrize(
    ("spec", "value"),
    [
        ("int16", 40000),
        ("uint16", -1),
        ("int32", 2**31),
        ("bcd16", 10000),
        ("bcd16", -1),
        ("bit", 2),
        ("string:2", "abc"),
        ("uint32", 1.5),
        ("int16", "x"),
    ],
)
def test_values_that_do_not_fit_are_refused(spec: str, value: object) -> None:
    with pytest.raises(CommandError):
        parse_value_type(spec).encode(value)  # type: ignore[arg-type]


@pytest.mark.parametrize("spec", ["float33", "string", "int16:4", "float32:XYZW", "1abc"])
def test_bad_type_specs_are_refused(spec: str) -> None:
    with pytest.raises(CommandError):
        parse_value_type(spec)


def test_invalid_bcd_words_raise_decode_error() -> None:
    with pytest.raises(DecodeError):
        parse_value_type("bcd16").decode((0x12AB,))
    with pytest.raises(DecodeError):
        parse_value_type("int32").decode((1,))


orders = st.sampled_from(list(WordOrder))

RANGES = {
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
    "bcd16": (0, 9999),
    "bcd32": (0, 99999999),
}


@given(st.sampled_from(sorted(RANGES)), orders, st.data())
def test_integer_round_trip(kind: str, order: WordOrder, data: st.DataObject) -> None:
    low, high = RANGES[kind]
    value = data.draw(st.integers(low, high))
    vtype = ValueType(kind, word_order=order)
    words = vtype.encode(value)
    assert len(words) == vtype.words
    assert all(0 <= w <= 0xFFFF for w in words)
    assert vtype.decode(words) == value


@given(orders, st.floats(width=32))
def test_float32_round_trip(order: WordOrder, value: float) -> None:
    vtype = ValueType("float32", word_order=order)
    back = vtype.decode(vtype.encode(value))
    assert isinstance(back, float)
    assert (math.isnan(back) and math.isnan(value)) or back == value


@given(orders, st.floats())
def test_float64_round_trip(order: WordOrder, value: float) -> None:
    vtype = ValueType("float64", word_order=order)
    back = vtype.decode(vtype.encode(value))
    assert isinstance(back, float)
    assert (math.isnan(back) and math.isnan(value)) or back == value


@given(
    st.text(alphabet=st.characters(min_codepoint=1, max_codepoint=127), max_size=20), st.booleans()
)
def test_ascii_string_round_trip(text: str, swap: bool) -> None:
    vtype = ValueType("string", length=20, swap_bytes=swap)
    assert vtype.decode(vtype.encode(text)) == text


@given(
    st.sampled_from(["int16", "uint32", "float64", "bcd16"]),
    st.lists(st.integers(0, 0xFFFF), max_size=16),
)
def test_decoding_arbitrary_words_raises_only_decode_error(spec: str, words: list[int]) -> None:
    vtype = parse_value_type(spec)
    with contextlib.suppress(DecodeError):
        words_to_values(vtype, words[: len(words) - len(words) % vtype.words])


def test_runs_of_values() -> None:
    vtype = parse_value_type("int32")
    words = values_to_words(vtype, [1, -1])
    assert words == [1, 0, 0xFFFF, 0xFFFF]
    assert words_to_values(vtype, words) == [1, -1]


def test_default_word_order_applies_only_when_the_spec_names_none() -> None:
    assert parse_value_type("uint32", default_word_order="ABCD").encode(0x12345678) == (
        0x1234,
        0x5678,
    )
    assert parse_value_type("uint32:CDAB", default_word_order="ABCD").encode(0x12345678) == (
        0x5678,
        0x1234,
    )
