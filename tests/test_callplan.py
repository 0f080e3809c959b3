"""Plans worked out once per call shape: the same bytes as building each request anew."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins._callplan import (
    PLAN_CACHE_SIZE,
    FrameWords,
    read_frames,
    typed_start,
    value_type,
    write_frames,
)
from aiofins.chunking import plan_memory
from aiofins.protocol.addresses import parse_address, parse_span
from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.commands.memory import MemoryAreaRead, MemoryAreaWrite
from aiofins.protocol.errors import AddressError, CommandError, DecodeError
from aiofins.protocol.values import ValueType, WordOrder


def test_address_text_is_parsed_once() -> None:
    first = parse_address("  d 1234 ")
    assert parse_address("  d 1234 ") is first
    assert parse_span("D1234", 10) is parse_span("D1234", 10)
    for _ in range(2):  # errors are raised every time, not kept
        with pytest.raises(AddressError, match="out of range"):
            parse_address("D40000")
        with pytest.raises(AddressError, match="run past the end"):
            parse_span("D32767", 2)
    with pytest.raises(AddressError, match="must be str"):
        parse_address(["D0"])  # type: ignore[arg-type]


@given(st.integers(0, 32767), st.integers(0, 5000), st.sampled_from([999, 269, 7]))
def test_read_frames_are_the_requests_the_chunk_plan_builds(
    word: int, count: int, limit: int
) -> None:
    count = min(count, 32768 - word)
    plan = read_frames(f"D{word}", count, limit)
    requests = [MemoryAreaRead(c.address, c.count) for c in plan_memory(
        MemoryAddress(0x82, word), count, limit)]  # fmt: skip
    assert plan.commands == tuple((1, 1, r.encode()) for r in requests)
    assert plan.sizes == tuple(2 * r.count for r in requests)
    assert read_frames(f"D{word}", count, limit) is plan
    data = [(bytes(range(256)) * 8)[: 2 * r.count] for r in requests]
    expected = [v for r, d in zip(requests, data, strict=True) for v in
                r.decode_response(d).values]  # fmt: skip
    assert plan.values(data) == expected


def test_read_frames_check_each_reply() -> None:
    plan = read_frames("D0", 1000, 999)
    with pytest.raises(DecodeError, match="expected 1 x 2 = 2 data bytes, got 4"):
        plan.values([bytes(1998), bytes(4)])
    bits = read_frames("CIO 0.03", 20, 7)
    assert bits.element_size == 1
    assert bits.values([b"\x01" * 7, b"\x00" * 7, b"\x01" * 6]) == [1] * 7 + [0] * 7 + [1] * 6
    with pytest.raises(CommandError, match="must not be negative"):
        read_frames("D0", -1, 999)


def test_a_one_frame_read_decodes_its_reply_frame_in_place() -> None:
    plan = read_frames("D100", 3, 999)
    head = bytes.fromhex("c00002000200000100070101") + b"\x00\x00"  # header, 0101, 0000
    assert plan.reply_size == 14 + 6
    assert plan.one(head + bytes.fromhex("0001fffe1234")) == [1, 0xFFFE, 0x1234]
    for data in (bytes(4), bytes(8)):  # a reply that is not 3 words: said, not decoded
        with pytest.raises(DecodeError, match="expected 3 x 2 = 6 data bytes, got"):
            plan.one(head + data)
    bits = read_frames("CIO 0.03", 2, 7)
    assert bits.one(head + b"\x01\x00") == [1, 0]
    assert read_frames("D0", 1000, 999).unpack_from is None  # two frames: values() joins


def test_frame_words_puts_each_reply_frames_data_in_its_place() -> None:
    plan = read_frames("D0", 2000, 999)  # 999 + 999 + 2 words
    assert plan.offsets == (0, 1998, 3996) and plan.ends == (1998, 3996, 4000)
    assert read_frames("D0", 0, 999).offsets == () == read_frames("D0", 0, 999).ends
    head = bytes.fromhex("c00002000200000100070101")
    seen: list[tuple[int, int]] = []
    sink = FrameWords(plan, lambda done, total: seen.append((done, total)))
    words = [(w * 7) & 0xFFFF for w in range(2000)]
    data = b"".join(w.to_bytes(2, "big") for w in words)
    for index in (2, 0, 1):  # in the order the replies come
        at, end = plan.offsets[index], plan.ends[index]
        flags = b"\x00\x40" if index == 1 else b"\x00\x00"
        sink.put(index, head + flags + data[at:end])
    assert seen == [(2, 2000), (1001, 2000), (2000, 2000)]
    assert sink.last is not None and sink.last[12:14] == b"\x00\x00"  # the last command's
    out = sink.words()
    assert out.tolist() == words
    out.append(1)  # no buffer of it left exported
    short = FrameWords(plan, None)
    with pytest.raises(DecodeError, match="expected 999 x 2 = 1998 data bytes, got 1996"):
        short.put(1, head + b"\x00\x00" + bytes(1996))
    short.release()


def test_write_frames_encode_what_memory_area_write_encodes() -> None:
    values = list(range(2500))
    plan = write_frames("D10", len(values), 997)
    assert write_frames("D10", len(values), 997) is plan
    frames = [plan.params(i, values) for i in range(len(plan.frames))]
    assert frames == [
        MemoryAreaWrite.from_values(c.address, values[c.offset : c.offset + c.count]).encode()
        for c in plan_memory(MemoryAddress(0x82, 10), len(values), 997)
    ]
    bits = write_frames("CIO 0.15", 3, 997)
    assert bits.params(0, [1, 0, 1]) == bytes.fromhex("30 0000 0F 0003 01 00 01")
    with pytest.raises(CommandError, match="bit value 2 at element 1"):
        bits.params(0, [1, 2, 0])
    with pytest.raises(CommandError, match="element value 65536 out of range"):
        plan.params(0, [65536] * 997)
    with pytest.raises(AddressError, match="cannot be written"):
        write_frames(MemoryAddress(0xB0 - 0x40, 0), 1, 997)  # 70: forced status, read only


def test_typed_specs_are_parsed_once() -> None:
    t = value_type("int32:ABCD", WordOrder.LOW_FIRST)
    assert t == ValueType("int32", word_order=WordOrder.HIGH_FIRST)
    assert value_type("int32:ABCD", WordOrder.LOW_FIRST) is t
    assert value_type("float32", WordOrder.HIGH_FIRST).word_order is WordOrder.HIGH_FIRST
    assert typed_start("D100", t, 3) == MemoryAddress(0x82, 100)
    with pytest.raises(CommandError, match="need word addresses"):
        typed_start("CIO 0.01", t, 1)


def test_the_caches_are_bounded() -> None:
    for cached in (read_frames, write_frames, value_type, typed_start):
        assert cached.cache_info().maxsize == PLAN_CACHE_SIZE
