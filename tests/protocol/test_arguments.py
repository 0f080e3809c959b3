"""The conversion layer of the manual-named methods: what users type → typed arguments."""

from __future__ import annotations

from datetime import datetime
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.addresses import format_address, parse_address
from aiofins.protocol.arguments import (
    address,
    addresses,
    element_data,
    force_entries,
    member,
    moment,
    names,
    payload,
    words,
)
from aiofins.protocol.commands.debug import ForcedSetResetEntry, ForceSpec
from aiofins.protocol.commands.memory import MemoryAreaWrite
from aiofins.protocol.errors import CommandError
from aiofins.protocol.files import Disk, FileTransferMode

D100 = parse_address("D100")
BIT = parse_address("CIO 0.01")


@given(st.lists(st.integers(0, 0xFFFF), max_size=50))
def test_word_lists_pack_as_from_values_does(values: list[int]) -> None:
    assert element_data(D100, values) == MemoryAreaWrite.from_values(D100, values).data
    assert element_data(D100, bytes(2 * len(values))) == bytes(2 * len(values))


@given(st.lists(st.integers(0, 1), max_size=16))
def test_bit_lists_are_one_byte_per_bit(values: list[int]) -> None:
    assert element_data(BIT, values) == bytes(values)


@given(st.integers(0, 32767))
def test_address_text_and_addresses_agree(word: int) -> None:
    text = f"D{word}"
    assert address(text) == parse_address(text) == address(parse_address(text))
    assert format_address(address(text)) == text
    assert addresses([text, "CIO 1.02"]) == (parse_address(text), parse_address("CIO 1.02"))
    assert addresses(text) == (parse_address(text),)


def test_members_by_name_alias_or_value() -> None:
    assert member(Disk, "card", "disk") is Disk.MEMORY_CARD
    assert member(Disk, "EM", "disk") is Disk.EM_FILE_MEMORY
    assert member(FileTransferMode, "area-to-file", "mode") is FileTransferMode.AREA_TO_FILE
    assert member(FileTransferMode, 1, "mode") == FileTransferMode.FILE_TO_AREA
    with pytest.raises(CommandError, match="mode must be one of area_to_file, file_to_area"):
        member(FileTransferMode, "sideways", "mode")


def test_the_other_conversions() -> None:
    assert words(range(3)) == (0, 1, 2)
    assert names("A.TXT") == ("A.TXT",) and names(["A", "B"]) == ("A", "B")
    assert moment("2026-01-02T03:04:05") == datetime(2026, 1, 2, 3, 4, 5)
    assert payload([1, 2]) == b"\x01\x02" and payload(bytearray(b"x")) == b"x"
    assert force_entries(("forced_set", "CIO 0.01")) == (
        ForcedSetResetEntry(ForceSpec.FORCED_SET, BIT),
    )
    untyped: Any = "12"  # what a caller without a type checker can pass
    for bad in (lambda: words(untyped), lambda: payload(untyped), lambda: payload([256])):
        with pytest.raises(CommandError):
            bad()
