"""Manual 5-2-2 as data: area codes, element sizes, ranges, and the 4-byte designation."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.areas import (
    AREAS,
    DataType,
    MemoryAddress,
    Series,
    area_codes,
    area_specs,
    check_address,
    element_size,
    find_spec,
    is_known_area_code,
)
from aiofins.protocol.errors import AddressError, DecodeError

CS, CV = Series.CS_CJ, Series.CV

# (series, code, first designation, last designation, bytes per element) straight from the
# manual's "Memory address" and "Length per element" columns, one line per table row.
MANUAL_ROWS = [
    (CS, 0x30, "000000", "17FF0F", 1),  # CIO bit
    (CS, 0x31, "000000", "01FF0F", 1),  # W bit
    (CS, 0x32, "000000", "01FF0F", 1),  # H bit
    (CS, 0x33, "000000", "03BF0F", 1),  # A bit (01BF0F read only, 01C000- read/write)
    (CS, 0x70, "000000", "17FF0F", 1),  # CIO bit with forced status
    (CS, 0x71, "000000", "01FF0F", 1),
    (CS, 0x72, "000000", "01FF0F", 1),
    (CS, 0xB0, "000000", "17FF00", 2),  # CIO word
    (CS, 0xB1, "000000", "01FF00", 2),
    (CS, 0xB2, "000000", "01FF00", 2),
    (CS, 0xB3, "000000", "03BF00", 2),
    (CS, 0xF0, "000000", "17FF00", 4),  # word with forced status
    (CS, 0xF1, "000000", "01FF00", 4),
    (CS, 0xF2, "000000", "01FF00", 4),
    (CS, 0x09, "000000", "8FFF00", 1),  # T 000000-0FFF00, C 800000-8FFF00
    (CS, 0x49, "000000", "8FFF00", 1),  # manual prints 8FFFF0: typo
    (CS, 0x89, "000000", "8FFF00", 2),
    (CS, 0x02, "000000", "7FFF0F", 1),
    (CS, 0x82, "000000", "7FFF00", 2),
    (CS, 0x20, "000000", "7FFF0F", 1),  # EM bank 0 bit
    (CS, 0x2F, "000000", "7FFF0F", 1),  # EM bank F bit
    (CS, 0xE0, "000000", "7FFF0F", 1),  # EM bank 10 hex bit
    (CS, 0xE8, "000000", "7FFF0F", 1),  # EM bank 18 hex bit
    (CS, 0xA0, "000000", "7FFF00", 2),
    (CS, 0xAF, "000000", "7FFF00", 2),
    (CS, 0x50, "000000", "7FFF00", 2),  # CJ2 only (note 2)
    (CS, 0x5F, "000000", "7FFF00", 2),
    (CS, 0x60, "000000", "7FFF00", 2),
    (CS, 0x68, "000000", "7FFF00", 2),
    (CS, 0x0A, "000000", "7FFF0F", 1),  # current bank bit
    (CS, 0x98, "000000", "7FFF00", 2),
    (CS, 0x06, "000000", "001F00", 1),  # TK
    (CS, 0x46, "000000", "001F00", 1),
    (CS, 0xDC, "010000", "010F00", 4),  # IR
    (CS, 0xBC, "020000", "020F00", 2),  # DR (and 0F0000 current bank number)
    (CS, 0x07, "000000", "200100", 1),  # clock pulses .. Access Error Flag
    (CV, 0x00, "000000", "0EBF0F", 1),  # CIO 000000-09FB0F, A 0B0000-0EBF0F
    (CV, 0x40, "000000", "09FB0F", 1),
    (CV, 0x80, "000000", "0EBF00", 2),
    (CV, 0xC0, "000000", "09FB00", 4),
    (CV, 0x01, "000000", "0FFF00", 1),  # T 000000-07FF00, C 080000-0FFF00
    (CV, 0x41, "000000", "0FFF00", 1),
    (CV, 0x81, "000000", "0FFF00", 2),
    (CV, 0x82, "000000", "7FFF00", 2),
    (CV, 0x90, "000000", "7FFF00", 2),
    (CV, 0x97, "000000", "7FFF00", 2),
    (CV, 0x98, "000000", "7FFF00", 2),
    (CV, 0x9C, "000300", "000600", 2),  # DR0-DR2 000300-000500, bank No. 000600
]


def _addr(code: int, designation: str) -> MemoryAddress:
    return MemoryAddress.decode(bytes([code]) + bytes.fromhex(designation))


@pytest.mark.parametrize(("series", "code", "first", "last", "size"), MANUAL_ROWS)
def test_manual_row_bounds_and_element_size(
    series: Series, code: int, first: str, last: str, size: int
) -> None:
    assert element_size(code) == size
    assert check_address(_addr(code, first), series).element_size == size
    assert check_address(_addr(code, last), series).code == code
    after = _addr(code, last)
    if after.word < 0xFFFF:
        with pytest.raises(AddressError, match="out of range"):
            check_address(MemoryAddress(code, after.word + 1, 0), series)


@pytest.mark.parametrize(
    ("series", "code", "word", "bit"),
    [
        (CS, 0x09, 0x1000, 0),  # between timers and counters
        (CS, 0x09, 0x9000, 0),
        (CS, 0xB0, 0x0000, 1),  # word designations have bit 00
        (CS, 0x30, 0x0000, 0x10),  # bits 00-0F
        (CS, 0x07, 0x0005, 0),  # no clock pulse at 0005
        (CS, 0x07, 0x100B, 0),  # 100B-100D are not in the table
        (CS, 0x07, 0x2000, 0),
        (CS, 0xBC, 0x0210, 0),  # DR16
        (CS, 0xBC, 0x0F01, 0),
        (CS, 0xDC, 0x00FF, 0),
        (CV, 0x00, 0x09FC, 0),  # CIO 2556
        (CV, 0x00, 0x0AFF, 0),  # gap before the Auxiliary Area
        (CV, 0x40, 0x0B00, 0),  # no forced A in CV
        (CV, 0x01, 0x1000, 0),
        (CV, 0x9C, 0x0002, 0),
        (CV, 0x9C, 0x0007, 0),
    ],
)
def test_out_of_range_designations_are_refused(
    series: Series, code: int, word: int, bit: int
) -> None:
    with pytest.raises(AddressError, match=f"{code:02X} hex"):
        check_address(MemoryAddress(code, word, bit), series)


def test_error_names_the_valid_range() -> None:
    with pytest.raises(AddressError) as info:
        check_address(MemoryAddress(0x82, 0x8000, 0), CS)
    assert "0000-7FFF hex" in str(info.value)
    with pytest.raises(AddressError) as info:
        check_address(MemoryAddress(0x30, 0, 0x10), CS)
    assert "bit 00-0F hex" in str(info.value)


@pytest.mark.parametrize(
    ("series", "code"),
    [(CS, 0x00), (CS, 0x80), (CS, 0x90), (CS, 0x9C), (CV, 0x30), (CV, 0xB0), (CV, 0x02)],
)
def test_codes_of_the_other_series_are_unknown(series: Series, code: int) -> None:
    assert not is_known_area_code(code, series)
    assert is_known_area_code(code)
    with pytest.raises(AddressError, match="does not exist"):
        check_address(MemoryAddress(code, 0, 0), series)


def test_code_sets() -> None:
    cs = area_codes(CS)
    cv = area_codes(CV)
    assert cs & cv == {0x82, 0x98}  # the only shared codes, with the same meaning
    # 26 fixed codes (30-33 70-72 B0-B3 F0-F2 09 49 89 02 82 0A 98 BC 06 46 DC 07),
    # bit + word codes of EM banks 0-18 hex, CJ2 codes 50-5F.
    assert len(cs) == 26 + 25 * 2 + 16
    assert cv == {0x00, 0x40, 0x80, 0xC0, 0x01, 0x41, 0x81, 0x82, 0x98, 0x9C, *range(0x90, 0x98)}
    with pytest.raises(AddressError, match="unknown memory area code 11"):
        element_size(0x11)


def test_read_only_auxiliary_area() -> None:
    for series, code, base in ((CS, 0xB3, 0x0000), (CV, 0x80, 0x0B00)):
        assert check_address(MemoryAddress(code, base + 447), series).read_only
        assert not check_address(MemoryAddress(code, base + 448), series).read_only


def test_flags_and_special_rows() -> None:
    on = find_spec(0x07, 0x100F, CS)
    off = find_spec(0x07, 0x100E, CS)
    assert on is not None and on.area == "P_On"
    assert off is not None and off.area == "P_Off"
    bank_no = check_address(MemoryAddress(0xBC, 0x0F00), CS)
    assert bank_no.data_type is DataType.BANK_NUMBER
    assert check_address(MemoryAddress(0x9C, 0x0006), CV).data_type is DataType.BANK_NUMBER
    assert check_address(MemoryAddress(0x53, 10), CS).alias  # CJ2 alternative of A3
    assert [s.bank for s in area_specs(0x60, CS)] == [0x10]
    assert [s.bank for s in area_specs(0xE8, CS)] == [0x18]


def test_table_rows_are_consistent() -> None:
    for spec in AREAS:
        assert spec.element_size == element_size(spec.code)
        assert spec.max_bit in (0, 15)
        assert spec.last_word <= 0xFFFF
        overlapping = [
            other
            for other in area_specs(spec.code, spec.series)
            if other is not spec and other.contains(spec.first_word)
        ]
        assert not overlapping, spec


@given(st.integers(0, 255), st.integers(0, 0xFFFF), st.integers(0, 255))
def test_encode_decode_round_trip(code: int, word: int, bit: int) -> None:
    address = MemoryAddress(code, word, bit)
    raw = address.encode()
    assert raw == bytes([code, word >> 8, word & 0xFF, bit])
    assert MemoryAddress.decode(raw) == address


@given(st.binary(max_size=8), st.sampled_from([None, CS, CV]))
def test_decode_arbitrary_bytes_raises_only_decode_error(raw: bytes, series: Series | None) -> None:
    try:
        address = MemoryAddress.decode(raw, series)
    except DecodeError as exc:
        assert exc.end_code in (0x1001, 0x1002, 0x1101, 0x1103)
        return
    assert len(raw) == 4
    if series is not None:
        check_address(address, series)


def test_decode_end_codes() -> None:
    with pytest.raises(DecodeError) as info:
        MemoryAddress.decode(b"\x82\x00")
    assert info.value.end_code == 0x1002
    with pytest.raises(DecodeError) as info:
        MemoryAddress.decode(b"\x82\x00\x00\x00\x00")
    assert info.value.end_code == 0x1001
    with pytest.raises(DecodeError) as info:
        MemoryAddress.decode(bytes.fromhex("11000000"), CS)
    assert info.value.end_code == 0x1101
    with pytest.raises(DecodeError) as info:
        MemoryAddress.decode(bytes.fromhex("82800000"), CS)
    assert info.value.end_code == 0x1103
    with pytest.raises(DecodeError) as info:
        MemoryAddress.decode(bytes.fromhex("30000010"), CS)  # bit 10 hex
    assert info.value.end_code == 0x1103
    assert MemoryAddress.decode(bytes.fromhex("9C000600"), CV) == MemoryAddress(0x9C, 6)


@pytest.mark.parametrize("bad", [(-1, 0, 0), (256, 0, 0), (0x82, 0x10000, 0), (0x82, 0, 256)])
def test_constructor_checks_byte_ranges(bad: tuple[int, int, int]) -> None:
    with pytest.raises(AddressError):
        MemoryAddress(*bad)


def test_offset_by_elements() -> None:
    assert MemoryAddress(0x82, 100) + 10 == MemoryAddress(0x82, 110)
    assert MemoryAddress(0x82, 100) - 100 == MemoryAddress(0x82, 0)
    assert MemoryAddress(0x30, 0, 15) + 1 == MemoryAddress(0x30, 1, 0)  # bits carry
    assert MemoryAddress(0x30, 1, 0).offset(-1) == MemoryAddress(0x30, 0, 15)
    assert MemoryAddress(0x30, 10, 13) + 35 == MemoryAddress(0x30, 13, 0)
    assert MemoryAddress(0x09, 0x8000) + 5 == MemoryAddress(0x09, 0x8005)  # one flag per counter
    assert MemoryAddress(0xDC, 0x0100) + 1 == MemoryAddress(0xDC, 0x0101)
    with pytest.raises(AddressError, match="leaves the word range"):
        MemoryAddress(0x82, 0xFFFF) + 1
    with pytest.raises(AddressError):
        MemoryAddress(0x30, 0, 0) - 1


@given(st.sampled_from(sorted(area_codes(CS))), st.integers(0, 0x7FFF), st.integers(-500, 500))
def test_offset_is_additive(code: int, word: int, n: int) -> None:
    start = MemoryAddress(code, word, 0)
    try:
        moved = start + n
    except AddressError:
        return
    assert moved - n == start
    assert moved.encode()[0] == code
