"""I/O memory commands 01 01 .. 01 05: golden bytes, server-side decoding, round trips."""

from __future__ import annotations

import contextlib
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.commands import Request
from aiofins.protocol.commands.memory import (
    OPERATIONS,
    MemoryAreaFill,
    MemoryAreaRead,
    MemoryAreaReadResult,
    MemoryAreaTransfer,
    MemoryAreaWrite,
    MultipleMemoryAreaRead,
    MultipleMemoryAreaReadItem,
    MultipleMemoryAreaReadResult,
)
from aiofins.protocol.errors import AddressError, CommandError, DecodeError

H = bytes.fromhex

# Area codes by element size (manual 5-2-2): bits, words, 4-byte elements.
BIT_CODES = [0x30, 0x31, 0x32, 0x33, 0x02, 0x20, 0x0A]
WORD_CODES = [0xB0, 0xB1, 0xB2, 0xB3, 0x89, 0x82, 0xA0, 0xA5, 0x98]
WIDE_CODES = [0xDC]  # index registers: 4 bytes, writable
# Codes addressed down to the bit (bits 0..15); other 1-byte codes always use bit 00.
BIT_ADDRESSED = frozenset([*BIT_CODES, 0x70, 0x71, 0x72])
READ_ONLY_CODES = [0xF0, 0xF1, 0xF2, 0x70, 0x71, 0x72, 0x09, 0x49, 0x06, 0x46, 0x07]
# Forced-status designations: read by 01 04 only (manual 5-3-5; not in 5-3-2's table).
FORCED_CODES = frozenset([0xF0, 0xF1, 0xF2, 0x70, 0x71, 0x72, 0x49])
SIZE = {
    **dict.fromkeys(BIT_CODES, 1),
    **dict.fromkeys(WORD_CODES, 2),
    0xDC: 4,
    0xF0: 4,
    0xF1: 4,
    0xF2: 4,
    **dict.fromkeys([0x70, 0x71, 0x72, 0x09, 0x49, 0x06, 0x46, 0x07], 1),
}


def D(word: int) -> MemoryAddress:
    return MemoryAddress(0x82, word, 0)


@st.composite
def addresses(draw: st.DrawFn, codes: list[int] | None = None) -> MemoryAddress:
    code = draw(st.sampled_from(codes if codes is not None else sorted(SIZE)))
    bit = draw(st.integers(0, 15)) if code in BIT_ADDRESSED else 0
    return MemoryAddress(code, draw(st.integers(0, 0xFFFF)), bit)


def element_data(size: int, count: int) -> st.SearchStrategy[bytes]:
    if size == 1:
        return st.lists(st.integers(0, 1), min_size=count, max_size=count).map(bytes)
    return st.binary(min_size=size * count, max_size=size * count)


# --- golden bytes -------------------------------------------------------------------------


def test_read_words_golden() -> None:
    # fins-wire-format.md 8.1: D100 x 10 words.
    request = MemoryAreaRead(D(100), 10)
    assert request.encode() == H("82 0064 00 000A")
    data = H("0001 0002 0003 0004 0005 0006 0007 0008 0009 000A")
    result = request.decode_response(data)
    assert result == MemoryAreaReadResult(data, 2)
    assert result.values == tuple(range(1, 11))
    assert result.count == 10
    assert result.encode() == data
    assert MemoryAreaRead.decode(H("82006400000A")) == request


def test_read_bits_golden() -> None:
    # Manual 5-2-1: bit 13 of CIO 0010 is 30 000A 0D.
    request = MemoryAreaRead(MemoryAddress(0x30, 10, 13), 3)
    assert request.encode() == H("30 000A 0D 0003")
    assert request.decode_response(H("01 00 01")).values == (1, 0, 1)


def test_read_word_with_forced_status_is_0104s() -> None:
    with pytest.raises(AddressError, match="01 04"):
        MemoryAreaRead(MemoryAddress(0xF0, 10), 2)
    request = MultipleMemoryAreaRead((MemoryAddress(0xF0, 10), MemoryAddress(0xF0, 11)))
    assert request.encode() == H("F0000A00 F0000B00")
    result = request.decode_response(H("F0 0000 1234  F0 FFFF 0001"))
    assert [item.value for item in result.items] == [0x00001234, 0xFFFF0001]


def test_read_zero_elements() -> None:
    request = MemoryAreaRead(D(0), 0)
    assert request.encode() == H("82 0000 00 0000")
    assert request.decode_response(b"").values == ()


def test_read_response_length_must_match() -> None:
    request = MemoryAreaRead(D(0), 2)
    for bad in (b"", H("0001"), H("0001 0002 03")):
        with pytest.raises(DecodeError):
            request.decode_response(bad)


def test_write_golden() -> None:
    request = MemoryAreaWrite(D(100), H("0001 0002 ABCD"))
    assert request.encode() == H("82 0064 00 0003 0001 0002 ABCD")
    assert request.count == 3
    assert request.values == (1, 2, 0xABCD)
    assert MemoryAreaWrite.from_values(D(100), [1, 2, 0xABCD]) == request
    assert MemoryAreaWrite.decode(request.encode()) == request
    request.decode_response(b"")  # no response data: returns None
    with pytest.raises(DecodeError):
        request.decode_response(b"\x00")


def test_write_bits_and_index_register_golden() -> None:
    bits = MemoryAreaWrite(MemoryAddress(0x31, 5, 2), H("01 00 01 01"))
    assert bits.encode() == H("31 0005 02 0004 01 00 01 01")
    ir = MemoryAreaWrite.from_values(MemoryAddress(0xDC, 0x0100), [0x12345678])
    assert ir.encode() == H("DC 0100 00 0001 12345678")


def test_fill_golden() -> None:
    request = MemoryAreaFill(MemoryAddress(0xB1, 5), 3, 0xABCD)
    assert request.encode() == H("B1 0005 00 0003 ABCD")
    assert MemoryAreaFill.decode(H("B1000500 0003 ABCD")) == request
    request.decode_response(b"")  # no response data: returns None


def test_multiple_read_golden() -> None:
    request = MultipleMemoryAreaRead(
        (D(100), MemoryAddress(0x30, 10, 13), MemoryAddress(0xF0, 1), MemoryAddress(0xDC, 0x100))
    )
    assert request.encode() == H("82006400 30000A0D F0000100 DC010000")
    data = H("82 1234  30 01  F0 0001 0002  DC 00000010")
    result = request.decode_response(data)
    assert result == MultipleMemoryAreaReadResult(
        (
            MultipleMemoryAreaReadItem(0x82, 0x1234),
            MultipleMemoryAreaReadItem(0x30, 1),
            MultipleMemoryAreaReadItem(0xF0, 0x00010002),
            MultipleMemoryAreaReadItem(0xDC, 0x10),
        )
    )
    assert result.values == (0x1234, 1, 0x00010002, 0x10)
    assert result.encode() == data
    assert MultipleMemoryAreaRead.decode(request.encode()) == request


def test_multiple_read_empty_is_a_no_op() -> None:
    request = MultipleMemoryAreaRead(())
    assert request.encode() == b""
    assert MultipleMemoryAreaRead.decode(b"") == request
    assert request.decode_response(b"") == MultipleMemoryAreaReadResult(())


def test_multiple_read_response_errors() -> None:
    request = MultipleMemoryAreaRead((D(0), D(1)))
    for bad in (H("82 0001"), H("82 0001 82 00"), H("82 0001 82 0002 82 0003"), H("11 00")):
        with pytest.raises(DecodeError):
            request.decode_response(bad)


def test_transfer_golden() -> None:
    request = MemoryAreaTransfer(D(0), MemoryAddress(0xB0, 0x10), 5)
    assert request.encode() == H("82 0000 00  B0 0010 00  0005")
    assert MemoryAreaTransfer.decode(request.encode()) == request
    request.decode_response(b"")  # no response data: returns None


def test_operation_table() -> None:
    assert [op.command_code() for op in OPERATIONS] == [0x0101, 0x0102, 0x0103, 0x0104, 0x0105]
    idempotent = {op.METHOD for op in OPERATIONS if op.IDEMPOTENT}
    assert idempotent == {"memory_area_read", "multiple_memory_area_read"}


# --- server side: malformed commands carry the end code a PLC answers ---------------------


@pytest.mark.parametrize(
    ("op", "params", "end_code"),
    [
        (MemoryAreaRead, H("82 0064"), 0x1002),
        (MemoryAreaRead, H("82 0064 00 000A 00"), 0x1001),
        (MemoryAreaRead, H("11 0064 00 000A"), 0x1101),
        (MemoryAreaRead, H("82 0064 00 03E8"), 0x110B),  # 1000 words
        (MemoryAreaRead, H("82 0064 03 0001"), 0x1103),  # bit of a word area
        (MemoryAreaRead, H("30 0064 10 0001"), 0x1103),  # bit 16
        (MemoryAreaRead, H("09 0064 01 0001"), 0x1103),  # completion flags: bit 00
        (MemoryAreaWrite, H("82 0064 00 0002 0001"), 0x1003),
        (MemoryAreaWrite, H("82 0064 00 0001 0001 0002"), 0x1003),
        (MemoryAreaWrite, H("F0 0064 00 0001 0000 0001"), 0x1101),
        (MemoryAreaWrite, H("30 0064 00 0002 01 02"), 0x110C),
        (MemoryAreaWrite, H("82 00"), 0x1002),
        (MemoryAreaFill, H("30 0064 00 0001 0001"), 0x1101),  # bit area
        (MemoryAreaFill, H("BC 0000 00 0001 0001"), 0x1101),  # EM bank number
        (MemoryAreaFill, H("82 0064 00 0001"), 0x1002),
        (MultipleMemoryAreaRead, H("82 0064 00 82"), 0x1002),
        (MultipleMemoryAreaRead, H("11 0064 00"), 0x1101),
        (MultipleMemoryAreaRead, H("82006400") * 168, 0x1001),
        (MemoryAreaTransfer, H("82 0000 00 F0 0000 00 0001"), 0x1101),
        (MemoryAreaTransfer, H("82 0000 00 82 0010 00 0001 00"), 0x1001),
    ],
)
def test_decode_rejects_with_end_code(op: type[Request[Any]], params: bytes, end_code: int) -> None:
    with pytest.raises(DecodeError) as info:
        op.decode(params)
    assert info.value.end_code == end_code


def test_multiple_read_limit_is_167() -> None:
    assert len(MultipleMemoryAreaRead((D(0),) * 167).encode()) == 668
    with pytest.raises(CommandError, match=r"0\.\.167"):
        MultipleMemoryAreaRead((D(0),) * 168)


# --- builders reject bad arguments before anything is sent --------------------------------


@pytest.mark.parametrize(
    ("build", "error", "match"),
    [
        (lambda: MemoryAreaRead(D(0), 1000), CommandError, r"0\.\.999"),
        (lambda: MemoryAreaRead(D(0), -1), CommandError, r"0\.\.999"),
        (lambda: MemoryAreaRead(MemoryAddress(0xDC, 0), 500), CommandError, r"0\.\.499"),
        (lambda: MemoryAreaRead(MemoryAddress(0x11, 0), 1), AddressError, "area code 11"),
        (lambda: MemoryAreaRead(MemoryAddress(0x82, 0, 1), 1), AddressError, "must be 0"),
        (lambda: MemoryAreaRead(MemoryAddress(0x30, 0, 16), 1), AddressError, r"0\.\.15"),
        (lambda: MemoryAreaRead("D100", 1), CommandError, "MemoryAddress"),  # type: ignore[arg-type]
        (lambda: MemoryAreaWrite(D(0), b"\x00" * 1996), CommandError, r"0\.\.997"),
        (
            lambda: MemoryAreaWrite(MemoryAddress(0xDC, 0), b"\x00" * 2000),
            CommandError,
            r"0\.\.498",
        ),
        (lambda: MemoryAreaWrite(D(0), b"\x00\x01\x02"), CommandError, "multiple of the element"),
        (lambda: MemoryAreaWrite(MemoryAddress(0x30, 0), b"\x02"), CommandError, r"0\.\.1"),
        (
            lambda: MemoryAreaWrite(MemoryAddress(0xF0, 0), b"\x00" * 4),
            AddressError,
            "cannot be written",
        ),
        (lambda: MemoryAreaWrite.from_values(D(0), [0x10000]), CommandError, r"0\.\.65535"),
        (lambda: MemoryAreaWrite(D(0), [1, 2]), CommandError, "bytes"),  # type: ignore[arg-type]
        (lambda: MemoryAreaFill(D(0), 0x10000, 0), CommandError, r"0\.\.65535"),
        (lambda: MemoryAreaFill(D(0), 1, 0x10000), CommandError, r"fill value .* 0\.\.65535"),
        (lambda: MemoryAreaFill(MemoryAddress(0x30, 0), 1, 1), AddressError, "not a word area"),
        (lambda: MultipleMemoryAreaRead(D(0)), CommandError, "sequence"),  # type: ignore[arg-type]
        (lambda: MemoryAreaTransfer(D(0), D(1), 0x10000), CommandError, r"0\.\.65535"),
        (lambda: MemoryAreaTransfer(MemoryAddress(0x30, 0), D(1), 1), AddressError, "source"),
        (lambda: MemoryAreaTransfer(D(0), MemoryAddress(0xF1, 0), 1), AddressError, "destination"),
        (lambda: MemoryAreaReadResult(b"\x00\x01\x02", 2), CommandError, "multiple"),
        (lambda: MultipleMemoryAreaReadItem(0x82, 0x10000), CommandError, r"0\.\.65535"),
    ],
)
def test_builders_reject(build: Any, error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        build()


def test_write_limit_997_words_fits_the_frame() -> None:
    assert len(MemoryAreaWrite(D(0), b"\x00" * 1994).encode()) == 2000


# --- hypothesis ---------------------------------------------------------------------------


@st.composite
def reads(draw: st.DrawFn) -> MemoryAreaRead:
    address = draw(addresses([code for code in sorted(SIZE) if code not in FORCED_CODES]))
    return MemoryAreaRead(address, draw(st.integers(0, min(999, 1998 // SIZE[address.area_code]))))


@st.composite
def writes(draw: st.DrawFn) -> MemoryAreaWrite:
    address = draw(addresses(BIT_CODES + WORD_CODES + WIDE_CODES))
    size = SIZE[address.area_code]
    count = draw(st.integers(0, min(997, 1994 // size)))
    return MemoryAreaWrite(address, draw(element_data(size, count)))


fills = st.builds(
    MemoryAreaFill, addresses(WORD_CODES), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)
)
transfers = st.builds(
    MemoryAreaTransfer, addresses(WORD_CODES), addresses(WORD_CODES), st.integers(0, 0xFFFF)
)
multiple_reads = st.lists(addresses(), max_size=167).map(
    lambda items: MultipleMemoryAreaRead(tuple(items))
)
requests = st.one_of(reads(), writes(), fills, transfers, multiple_reads)


@given(requests)
def test_request_round_trip(request: Request[Any]) -> None:
    assert type(request).decode(request.encode()) == request


@given(reads(), st.data())
def test_read_result_round_trip(request: MemoryAreaRead, data: st.DataObject) -> None:
    size = SIZE[request.address.area_code]
    result = MemoryAreaReadResult(data.draw(element_data(size, request.count)), size)
    assert request.decode_response(result.encode()) == result
    assert MemoryAreaReadResult.from_values(result.values, size) == result


@given(multiple_reads, st.data())
def test_multiple_read_result_round_trip(
    request: MultipleMemoryAreaRead, data: st.DataObject
) -> None:
    items = tuple(
        MultipleMemoryAreaReadItem(
            address.area_code,
            data.draw(st.integers(0, (1 << (8 * SIZE[address.area_code])) - 1)),
        )
        for address in request.addresses
    )
    result = MultipleMemoryAreaReadResult(items)
    assert request.decode_response(result.encode()) == result


@given(st.sampled_from(OPERATIONS), st.binary(max_size=64))
def test_arbitrary_params_only_raise_decode_error(op: type[Request[Any]], params: bytes) -> None:
    try:
        request = op.decode(params)
    except DecodeError as exc:
        assert exc.end_code is not None
    else:
        assert type(request).decode(request.encode()) == request


RESPONSE_REQUESTS = [
    MemoryAreaRead(D(0), 3),
    MemoryAreaRead(MemoryAddress(0x30, 0), 2),
    MemoryAreaWrite(D(0), b"\x00\x01"),
    MemoryAreaFill(D(0), 1, 1),
    MemoryAreaTransfer(D(0), D(1), 1),
    MultipleMemoryAreaRead((D(0), MemoryAddress(0x30, 0, 1), MemoryAddress(0xF0, 0))),
]


@given(st.sampled_from(RESPONSE_REQUESTS), st.binary(max_size=32))
def test_arbitrary_response_only_raises_decode_error(request: Request[Any], data: bytes) -> None:
    with contextlib.suppress(DecodeError):
        request.decode_response(data)


@pytest.mark.parametrize("code", READ_ONLY_CODES, ids=lambda code: f"{code:02X}")
def test_forced_status_and_flag_areas_are_read_only(code: int) -> None:
    address = MemoryAddress(code, 0)
    if code not in FORCED_CODES:
        assert MemoryAreaRead(address, 1).element_size == SIZE[code]
    assert MultipleMemoryAreaRead((address,)).encode() == address.encode()
    with pytest.raises(AddressError, match="cannot be written"):
        MemoryAreaWrite(address, bytes(SIZE[code]))
    with pytest.raises(DecodeError) as info:
        MemoryAreaWrite.decode(address.encode() + b"\x00\x01" + bytes(SIZE[code]))
    assert info.value.end_code == 0x1101


@pytest.mark.parametrize("code", [0x70, 0x71, 0x72, 0xF0, 0xF1, 0xF2, 0x49, 0x40, 0xC0, 0x41])
def test_forced_status_is_read_by_0104_not_0101(code: int) -> None:
    """Manual 5-3-2's area table has no forced-status codes; 5-3-5's (01 04) has them."""
    address = MemoryAddress(code, 10, 0)
    with pytest.raises(AddressError, match="MULTIPLE MEMORY AREA READ") as info:
        MemoryAreaRead(address, 1)
    assert info.value.end_code == 0x1101
    MultipleMemoryAreaRead((address,))  # accepted there


@pytest.mark.parametrize(
    ("code", "word", "count", "refused"),
    [
        (0xBC, 0x0F00, 1, True),  # CS/CJ: EM current bank number
        (0xBC, 0x0200, 16, False),  # DR0-DR15
        (0x9C, 0x0006, 1, True),  # CV: EM current bank number
        (0x9C, 0x0003, 4, True),  # DR0-DR2, then the bank number
        (0x9C, 0x0003, 3, False),
    ],
)
def test_0102_cannot_write_the_em_current_bank_number(
    code: int, word: int, count: int, refused: bool
) -> None:
    """Manual 5-3-3's table lists BC/9C as Data Register only (5-3-2's adds the bank No.)."""
    data = bytes(2 * count)
    if not refused:
        MemoryAreaWrite(MemoryAddress(code, word), data)
        return
    with pytest.raises(AddressError, match="EM current bank number") as info:
        MemoryAreaWrite(MemoryAddress(code, word), data)
    assert info.value.end_code == 0x1101
    MemoryAreaRead(MemoryAddress(code, word), count)  # reading it is fine


def test_0102_cannot_write_cv_bits() -> None:
    """Manual 5-3-3: the CIO/AR bit rows have "---" in the CV column (code 00)."""
    with pytest.raises(AddressError, match="cannot be written"):
        MemoryAreaWrite(MemoryAddress(0x00, 10, 3), b"\x01")
    MemoryAreaRead(MemoryAddress(0x00, 10, 3), 1)
