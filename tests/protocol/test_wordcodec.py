"""The whole-run codecs against the per-element definitions they replace.

The reference functions below are the definitions the library used before (one
``int.from_bytes`` / ``to_bytes`` per element, one value at a time through its word order);
the fast paths must agree with them on every input, and fall back (``None``) exactly where
the per-element path raises.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.commands.memory import MemoryAreaReadResult, MemoryAreaWrite
from aiofins.protocol.errors import CommandError, DecodeError
from aiofins.protocol.values import (
    Value,
    ValueType,
    WordOrder,
    values_to_words,
    words_to_values,
)
from aiofins.protocol.wordcodec import (
    pack_elements,
    unpack_elements,
    values_from_words,
    words_from_values,
)

# -- reference definitions --------------------------------------------------------------


def ref_unpack(data: bytes, size: int) -> tuple[int, ...]:
    return tuple(int.from_bytes(data[i : i + size], "big") for i in range(0, len(data), size))


def ref_pack(values: Sequence[int], size: int) -> bytes:
    return b"".join(v.to_bytes(size, "big") for v in values)


_STRUCT = {
    "int16": ">h",
    "uint16": ">H",
    "int32": ">i",
    "uint32": ">I",
    "int64": ">q",
    "uint64": ">Q",
    "float32": ">f",
    "float64": ">d",
}


def ref_memory_words(value_bytes: bytes, order: WordOrder) -> list[int]:
    """Value bytes (most significant first) -> words in memory order, spelled out."""
    pairs = [value_bytes[i : i + 2] for i in range(0, len(value_bytes), 2)]
    if order in (WordOrder.LOW_FIRST, WordOrder.LOW_FIRST_SWAPPED):
        pairs.reverse()
    if order in (WordOrder.HIGH_FIRST_SWAPPED, WordOrder.LOW_FIRST_SWAPPED):
        pairs = [p[::-1] for p in pairs]
    return [p[0] * 256 + p[1] for p in pairs]


def ref_value_bytes(words: Sequence[int], order: WordOrder) -> bytes:
    pairs = [bytes((w >> 8, w & 0xFF)) for w in words]
    if order in (WordOrder.HIGH_FIRST_SWAPPED, WordOrder.LOW_FIRST_SWAPPED):
        pairs = [p[::-1] for p in pairs]
    if order in (WordOrder.LOW_FIRST, WordOrder.LOW_FIRST_SWAPPED):
        pairs.reverse()
    return b"".join(pairs)


def ref_encode(vtype: ValueType, values: Sequence[Value]) -> list[int]:
    out: list[int] = []
    for v in values:
        if vtype.kind in _STRUCT:
            raw = struct.pack(_STRUCT[vtype.kind], v)
        elif vtype.kind in ("bcd16", "bcd32"):
            digits = 4 * vtype.words
            raw = int(f"{v:0{digits}d}", 16).to_bytes(digits // 2, "big")
        else:
            out.append(int(v))
            continue
        out += ref_memory_words(raw, vtype.word_order)
    return out


def ref_decode(vtype: ValueType, words: Sequence[int]) -> list[Value]:
    n = vtype.words
    out: list[Value] = []
    for i in range(0, len(words), n):
        part = words[i : i + n]
        if vtype.kind == "bit":
            out.append(bool(part[0] & 1))
            continue
        raw = ref_value_bytes(part, vtype.word_order)
        if vtype.kind in _STRUCT:
            out.append(struct.unpack(_STRUCT[vtype.kind], raw)[0])
        else:
            out.append(int(raw.hex()))
    return out


# -- elements ---------------------------------------------------------------------------

sizes = st.sampled_from([1, 2, 4])


@given(sizes, st.data())
def test_unpack_elements_matches_per_element(size: int, data: st.DataObject) -> None:
    n = data.draw(st.integers(0, 300))
    raw = data.draw(st.binary(min_size=n * size, max_size=n * size))
    assert unpack_elements(raw, size) == ref_unpack(raw, size)
    assert MemoryAreaReadResult(raw, size).values == ref_unpack(raw, size)


@given(sizes, st.data())
def test_pack_elements_matches_per_element(size: int, data: st.DataObject) -> None:
    values = data.draw(st.lists(st.integers(0, (1 << (8 * size)) - 1), max_size=300))
    assert pack_elements(values, size) == ref_pack(values, size)
    assert MemoryAreaReadResult.from_values(values, size).data == ref_pack(values, size)


@given(sizes, st.lists(st.integers(-5, 1 << 33), min_size=1, max_size=20))
def test_pack_elements_refuses_what_the_per_element_path_refuses(
    size: int, values: list[int]
) -> None:
    limit = (1 << (8 * size)) - 1
    if all(0 <= v <= limit for v in values):
        assert pack_elements(values, size) == ref_pack(values, size)
    else:
        assert pack_elements(values, size) is None
        bad = next(v for v in values if not 0 <= v <= limit)
        with pytest.raises(CommandError, match=f"value {bad} out of range 0..{limit}"):
            MemoryAreaReadResult.from_values(values, size)


def test_pack_elements_leaves_other_types_to_the_per_element_path() -> None:
    assert pack_elements([1, 2.0], 2) is None  # type: ignore[list-item]
    assert pack_elements([True, 1], 1) is None  # bool: the per-element path takes it
    assert MemoryAreaReadResult.from_values([True, 1], 1).data == b"\x01\x01"
    with pytest.raises(CommandError, match=r"value 2\.0 out of range"):
        MemoryAreaReadResult.from_values([1, 2.0], 2)  # type: ignore[list-item]


@given(st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=997))
def test_memory_area_write_from_values_words(values: list[int]) -> None:
    w = MemoryAreaWrite.from_values(MemoryAddress(0x82, 0, 0), values)
    assert w.data == ref_pack(values, 2)
    assert w.values == tuple(values)


def test_memory_area_write_bit_data_names_the_bad_element() -> None:
    with pytest.raises(CommandError, match="bit value 2 at element 1"):
        MemoryAreaWrite(MemoryAddress(0x30, 0, 0), b"\x01\x02\x00")


# -- typed values -----------------------------------------------------------------------

orders = st.sampled_from(list(WordOrder))
numeric = st.sampled_from(list(_STRUCT))


def _values_for(kind: str) -> st.SearchStrategy[Value]:
    if kind == "float32":
        return st.floats(width=32, allow_nan=False)
    if kind == "float64":
        return st.floats(allow_nan=False)
    fmt = struct.Struct(_STRUCT[kind])
    bits = 8 * fmt.size
    if kind.startswith("u"):
        return st.integers(0, (1 << bits) - 1)
    return st.integers(-(1 << (bits - 1)), (1 << (bits - 1)) - 1)


@given(numeric, orders, st.data())
def test_numeric_runs_match_per_value(kind: str, order: WordOrder, data: st.DataObject) -> None:
    vtype = ValueType(kind, word_order=order)
    values = data.draw(st.lists(_values_for(kind), max_size=40))
    words = values_to_words(vtype, values)
    assert words == ref_encode(vtype, values)
    assert words == [w for v in values for w in vtype.encode(v)]
    assert words_to_values(vtype, words) == values


@given(st.sampled_from(["bcd16", "bcd32", "bit", *_STRUCT]), orders, st.data())
def test_any_words_decode_as_per_value(kind: str, order: WordOrder, data: st.DataObject) -> None:
    vtype = ValueType(kind, word_order=order)
    n = data.draw(st.integers(0, 30))
    words = data.draw(st.lists(st.integers(0, 0xFFFF), min_size=n * vtype.words,
                               max_size=n * vtype.words))  # fmt: skip
    try:
        expected: list[Value] | None = ref_decode(vtype, words)
    except ValueError:  # a BCD nibble over 9
        expected = None
    fast = values_from_words(vtype, words)
    if expected is None:
        assert fast is None
        with pytest.raises(DecodeError, match="BCD"):
            words_to_values(vtype, words)
        return
    got = words_to_values(vtype, words)
    same = [
        a == b
        or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))
        for a, b in zip(got, expected, strict=True)
    ]
    assert all(same)
    assert len(got) == len(expected)


@given(st.sampled_from(["bcd16", "bcd32"]), orders, st.data())
def test_bcd_runs_match_per_value(kind: str, order: WordOrder, data: st.DataObject) -> None:
    vtype = ValueType(kind, word_order=order)
    values = data.draw(st.lists(st.integers(0, 10 ** (4 * vtype.words) - 1), max_size=40))
    words = values_to_words(vtype, values)
    assert words == ref_encode(vtype, values)
    assert words_to_values(vtype, words) == values


@pytest.mark.parametrize(
    ("kind", "values", "message"),
    [
        ("int16", [1, 40000], "does not fit in int16"),
        ("uint32", [1, -1], "does not fit in uint32"),
        ("int32", [1, 2.5], "needs an integer"),
        ("float32", [1.0, "x"], "needs a number"),
        ("float32", [1e300], "overflows float32"),
        ("bcd16", [10000], "does not fit in 4 BCD digits"),
        ("bit", [0, 2], "bit needs 0/1"),
    ],
)
def test_bad_values_in_a_run_are_named(kind: str, values: list[Value], message: str) -> None:
    vtype = ValueType(kind)
    assert words_from_values(vtype, values) is None
    with pytest.raises(CommandError, match=message):
        values_to_words(vtype, values)


def test_values_of_other_int_like_types_take_the_per_value_path() -> None:
    vtype = ValueType("int32")
    assert words_from_values(vtype, [True, 2]) is None
    assert values_to_words(vtype, [True, 2]) == [1, 0, 2, 0]


def test_words_out_of_range_are_named() -> None:
    for kind in ("uint16", "float32", "bcd16", "bit"):
        vtype = ValueType(kind)
        words = [0] * vtype.words + [0x10000] + [0] * (vtype.words - 1)
        assert values_from_words(vtype, words) is None
        with pytest.raises(DecodeError, match="word value 65536 out of range"):
            words_to_values(vtype, words)


def test_strings_keep_the_per_value_path() -> None:
    vtype = ValueType("string", length=4)
    assert words_from_values(vtype, ["ab"]) is None
    assert values_to_words(vtype, ["ab", "cd"]) == [0x6162, 0, 0x6364, 0]
    assert words_to_values(vtype, [0x6162, 0, 0x6364, 0]) == ["ab", "cd"]
