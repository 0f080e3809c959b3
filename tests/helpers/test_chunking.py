"""Chunk plans never exceed a limit and cover every element exactly once, in order."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.chunking import (
    offset_address,
    plan_file,
    plan_memory,
    plan_multiple,
    plan_parameter,
    plan_program,
    split,
)
from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.errors import CommandError


def test_full_dm_read_on_ethernet_and_sysmac_link() -> None:
    dm0 = MemoryAddress(0x82, 0, 0)
    eth = plan_memory(dm0, 32768, 999)
    assert len(eth) == 33
    assert eth[1].address == MemoryAddress(0x82, 999, 0)
    assert eth[-1].count == 32768 - 32 * 999
    assert len(plan_memory(dm0, 32768, 269)) == 122


def test_bit_addresses_carry_into_the_next_word() -> None:
    cio = MemoryAddress(0x30, 10, 14)
    assert offset_address(cio, 1) == MemoryAddress(0x30, 10, 15)
    assert offset_address(cio, 2) == MemoryAddress(0x30, 11, 0)
    assert offset_address(cio, 18) == MemoryAddress(0x30, 12, 0)
    # Completion flags advance one timer per element.
    assert offset_address(MemoryAddress(0x09, 5, 0), 3) == MemoryAddress(0x09, 8, 0)


def test_program_blocks_are_multiples_of_four_with_last_marker() -> None:
    blocks = plan_program(0, 2000, 996)
    assert [(b.start, b.size, b.last) for b in blocks] == [
        (0, 996, False),
        (996, 996, False),
        (1992, 8, True),
    ]
    with pytest.raises(CommandError, match="multiple of 4"):
        plan_program(0, 10, 992)


def test_parameter_and_file_blocks() -> None:
    assert [(b.start, b.size, b.last) for b in plan_parameter(0, 1000)] == [
        (0, 498, False),
        (498, 498, False),
        (996, 4, True),
    ]
    assert [(b.start, b.size) for b in plan_file(10, 5, 2)] == [(10, 2), (12, 2), (14, 1)]


def test_zero_elements_need_no_frame_and_bad_limits_are_refused() -> None:
    assert plan_memory(MemoryAddress(0x82, 0, 0), 0, 999) == []
    with pytest.raises(CommandError):
        split(10, 0)
    with pytest.raises(CommandError):
        split(-1, 10)


@given(st.integers(0, 40000), st.integers(1, 2000))
def test_split_covers_exactly_once(total: int, limit: int) -> None:
    pieces = split(total, limit)
    assert all(1 <= n <= limit for _, n in pieces)
    covered = [i for off, n in pieces for i in range(off, off + n)]
    assert covered == list(range(total))


@given(
    st.sampled_from([0x30, 0x82, 0x02, 0x09, 0xB1]),
    st.integers(0, 100),
    st.integers(0, 15),
    st.integers(0, 3000),
    st.integers(1, 999),
)
def test_memory_plan_addresses_match_element_offsets(
    area: int, word: int, bit: int, count: int, limit: int
) -> None:
    start = MemoryAddress(area, word, bit if area in (0x30, 0x02) else 0)
    chunks = plan_memory(start, count, limit)
    assert sum(c.count for c in chunks) == count
    assert all(c.count <= limit for c in chunks)
    for c in chunks:
        assert c.address == offset_address(start, c.offset)


@given(st.lists(st.integers(0, 100), max_size=400), st.integers(1, 167))
def test_multiple_plan_keeps_order(words: list[int], limit: int) -> None:
    addresses = [MemoryAddress(0x82, w, 0) for w in words]
    frames = plan_multiple(addresses, limit)
    assert all(1 <= len(f) <= limit for f in frames)
    assert [a for f in frames for a in f] == addresses


@given(st.integers(0, 5000).map(lambda n: n * 4), st.sampled_from([992, 996, 100]))
def test_program_plan_limits(size: int, limit: int) -> None:
    blocks = plan_program(0, size, limit)
    assert all(b.size % 4 == 0 and b.size <= limit for b in blocks)
    assert sum(b.size for b in blocks) == size
    assert [b.last for b in blocks] == [False] * (len(blocks) - 1) + [True] * bool(blocks)
