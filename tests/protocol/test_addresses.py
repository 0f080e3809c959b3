"""Address text <-> designation: the manual's examples byte for byte, the syntax, ranges."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from aiofins.protocol.addresses import format_address, parse_address, parse_span
from aiofins.protocol.areas import (
    AREAS,
    FLAGS,
    AreaSpec,
    DataType,
    MemoryAddress,
    Series,
    check_address,
)
from aiofins.protocol.errors import AddressError

CS, CV = Series.CS_CJ, Series.CV

# Every example of manual 5-2-1/5-2-2, written as the manual writes the address (the
# forced-status rows with this library's "forced" keyword), and the designation it prints.
MANUAL_EXAMPLES = [
    ("CIO 0010", "B0000A00"),
    ("CIO 001013", "30000A0D"),  # bit 13 of CIO 0010 (also the 5-2-1 example)
    ("W010", "B1000A00"),  # the manual prints "B10000A00 hex" (9 digits): typo
    ("W01013", "31000A0D"),
    ("H010", "B2000A00"),
    ("H01013", "32000A0D"),
    ("CIO 001013 forced", "70000A0D"),
    ("CIO 0010 forced", "F0000A00"),
    ("T0010.C", "09000A00"),  # "T0010 Completion Flag"
    ("D00010", "82000A00"),
    ("E_3_00010", "A3000A00"),
    ("E00010", "98000A00"),  # "Current EM bank 00010 value"
    ("W005", "B1000500"),  # 5-2-1 "Example: Reading W005"
]


@pytest.mark.parametrize(("text", "designation"), MANUAL_EXAMPLES)
def test_manual_examples(text: str, designation: str) -> None:
    address = parse_address(text)
    assert address.encode() == bytes.fromhex(designation)
    assert parse_address(str(address)) == address


# What people write -> bytes (CS/CJ).
SYNTAX = [
    ("D100", "82006400", "D100"),
    ("DM100", "82006400", "D100"),
    ("d 100", "82006400", "D100"),
    ("D100.05", "02006405", "D100.05"),
    ("D0000000", "02000000", "D0.00"),  # manual's fixed width: D + 5 word digits + 2 bit digits
    ("D3276715", "027FFF0F", "D32767.15"),
    ("CIO 10.13", "30000A0D", "CIO10.13"),
    ("CIO10", "B0000A00", "CIO10"),
    ("10.13", "30000A0D", "CIO10.13"),
    ("10", "B0000A00", "CIO10"),
    ("CIO 6143.15", "3017FF0F", "CIO6143.15"),
    ("W5", "B1000500", "W5"),
    ("WR5", "B1000500", "W5"),
    ("W5.01", "31000501", "W5.01"),
    ("w511.15", "3101FF0F", "W511.15"),
    ("H10", "B2000A00", "H10"),
    ("HR10.00", "32000A00", "H10.00"),
    ("A448", "B301C000", "A448"),
    ("AR959", "B303BF00", "A959"),
    ("A447.15", "3301BF0F", "A447.15"),
    ("A44715", "3301BF0F", "A447.15"),
    ("T10", "89000A00", "T10"),
    ("TIM0010", "89000A00", "T10"),
    ("T10.C", "09000A00", "T10.C"),
    ("t10.c", "09000A00", "T10.C"),
    ("T4095.C!", "490FFF00", "T4095.C!"),
    ("T10.C forced", "49000A00", "T10.C!"),
    ("C20", "89801400", "C20"),
    ("CNT20", "89801400", "C20"),
    ("C20.C", "09801400", "C20.C"),
    ("C4095", "898FFF00", "C4095"),
    ("E3_100", "A3006400", "E3_100"),
    ("EM3_100", "A3006400", "E3_100"),
    ("E3_100.05", "23006405", "E3_100.05"),
    ("E3_0010005", "23006405", "E3_100.05"),
    ("EF_32767", "AF7FFF00", "EF_32767"),
    ("E10_100", "60006400", "E10_100"),  # bank 10 hex = 16
    ("E18_0.15", "E800000F", "E18_0.15"),
    ("E0_0000000", "20000000", "E0_0.00"),
    ("E100", "98006400", "E100"),
    ("EM100", "98006400", "E100"),
    ("E100.05", "0A006405", "E100.05"),
    ("EMBANK", "BC0F0000", "EMBANK"),
    ("IR0", "DC010000", "IR0"),
    ("IR15", "DC010F00", "IR15"),
    ("DR3", "BC020300", "DR3"),
    ("TK5", "06000500", "TK5"),
    ("TK0031", "06001F00", "TK31"),
    ("TK5.S", "46000500", "TK5.S"),
    ("CIO10.13!", "70000A0D", "CIO10.13!"),
    ("CIO 10.13 FORCED", "70000A0D", "CIO10.13!"),
    ("W5_forced", "F1000500", "W5!"),
    ("H5.01!", "72000501", "H5.01!"),
    ("H5!", "F2000500", "H5!"),
    ("#82:0064:00", "82006400", "D100"),
    ("#53000A00", "53000A00", "#53:000A:00"),  # CJ2 code for EM bank 3: kept raw
]


@pytest.mark.parametrize(("text", "designation", "canonical"), SYNTAX)
def test_syntax(text: str, designation: str, canonical: str) -> None:
    address = parse_address(text)
    assert address.encode() == bytes.fromhex(designation)
    assert str(address) == canonical
    assert parse_address(canonical) == address


@pytest.mark.parametrize(("word", "name", "manual_name"), FLAGS)
def test_clock_pulses_and_condition_flags(word: int, name: str, manual_name: str) -> None:
    address = parse_address(name)
    assert address == MemoryAddress(0x07, word, 0)
    assert parse_address(name.lower()) == address
    assert str(address) == name
    assert check_address(address, CS).name == manual_name


def test_flag_addresses_of_the_manual() -> None:
    expected = {
        "P_1min": "07000000",
        "P_1s": "07000100",
        "P_0_2s": "07000200",
        "P_0_1s": "07000300",
        "P_0_02s": "07000400",
        "P_ER": "07100000",
        "P_CY": "07100100",
        "P_GT": "07100200",
        "P_EQ": "07100300",
        "P_LT": "07100400",
        "P_N": "07100500",
        "P_OF": "07100600",
        "P_UF": "07100700",
        "P_GE": "07100800",
        "P_NE": "07100900",
        "P_LE": "07100A00",
        "P_Off": "07100E00",  # manual: "Always OFF Flag (ON) 100E00" - symbols swapped
        "P_On": "07100F00",
        "P_AER": "07200100",
    }
    assert {name: parse_address(name).encode().hex().upper() for name in expected} == expected


CV_SYNTAX = [
    ("CIO 10.13", "00000A0D", "CIO10.13"),
    ("CIO 2555", "8009FB00", "CIO2555"),
    ("CIO 10.13!", "40000A0D", "CIO10.13!"),
    ("CIO 10 forced", "C0000A00", "CIO10!"),
    ("A0", "800B0000", "A0"),
    ("A959", "800EBF00", "A959"),
    ("A448.15", "000CC00F", "A448.15"),
    ("T10", "81000A00", "T10"),
    ("T2047.C", "0107FF00", "T2047.C"),
    ("C0.C!", "41080000", "C0.C!"),
    ("C2047", "810FFF00", "C2047"),
    ("D32767", "827FFF00", "D32767"),
    ("E0_0", "90000000", "E0_0"),
    ("E7_32767", "977FFF00", "E7_32767"),
    ("E100", "98006400", "E100"),
    ("DR0", "9C000300", "DR0"),
    ("DR2", "9C000500", "DR2"),
    ("EMBANK", "9C000600", "EMBANK"),
]


@pytest.mark.parametrize(("text", "designation", "canonical"), CV_SYNTAX)
def test_cv_mode(text: str, designation: str, canonical: str) -> None:
    address = parse_address(text, CV)
    assert address.encode() == bytes.fromhex(designation)
    assert format_address(address, CV) == canonical
    assert str(address) == canonical
    assert parse_address(canonical, CV) == address


@pytest.mark.parametrize(
    ("text", "series", "message"),
    [
        ("D32768", CS, "valid: D0-D32767"),
        ("CIO 6144", CS, "valid: CIO0-CIO6143"),
        ("CIO 2556", CV, "valid: CIO0-CIO2555"),
        ("W512", CS, "valid: W0-W511"),
        ("H512.00", CS, "valid: H0-H511"),
        ("A960", CS, "A0-A447 (read only), A448-A959"),
        ("T4096", CS, "valid: T0-T4095"),
        ("C4096.C", CS, "valid: C0-C4095"),
        ("T2048", CV, "valid: T0-T2047"),
        ("E19_0", CS, "0-18 hex"),
        ("E8_0", CV, "EM Area bank 8 word does not exist"),
        ("E3_32768", CS, "valid: E3_0-E3_32767"),
        ("E32768", CS, "valid: E0-E32767"),
        ("IR16", CS, "valid: IR0-IR15"),
        ("DR16", CS, "valid: DR0-DR15"),
        ("DR3", CV, "valid: DR0-DR2"),
        ("TK32", CS, "valid: TK0-TK31"),
        ("W5.16", CS, "bit 16 out of range 00-15"),
        ("CIO 10.99", CS, "out of range 00-15"),
        ("T10.05", CS, "no bit designations"),
        ("T10!", CS, "no forced-status"),
        ("A5!", CS, "does not exist"),
        ("IR1.C", CS, "no suffixes"),
        ("CIO1.X", CS, "unknown suffix"),
        ("T1.S", CS, "unknown suffix"),
        ("TK1.C", CS, "unknown suffix"),
        ("P_On!", CS, "no forced-status"),
        ("P_On", CV, "Always ON Flag does not exist in the CVM1/CV series"),
        ("W10", CV, "Work Area word does not exist in the CVM1/CV series"),
        ("D10.00", CV, "DM Area bit does not exist"),
        ("E100.00", CV, "EM Area current bank bit does not exist"),
        ("IR0", CV, "does not exist"),
        ("X10", CS, "unknown area 'X'"),
        ("", CS, "empty"),
        ("D", CS, "not an address"),
        ("D1.2.3", CS, "not an address"),
        ("#11:0000:00", CS, "11 hex does not exist"),
        ("#82:8000:00", CS, "out of range"),
        ("#30:0000:10", CS, "bit 10 hex is out of range"),
        ("D" + "1" * 5000, CS, "not an address"),  # bounded: no huge int() conversion
        ("D\u0661\u0662", CS, "not an address"),  # Arabic-Indic digits are not accepted
        ("W5.123", CS, "not an address"),
        ("D999999999", CS, "valid: D0-D32767"),
    ],
)
def test_errors_name_the_valid_range(text: str, series: Series, message: str) -> None:
    with pytest.raises(AddressError) as info:
        parse_address(text, series)
    assert message in str(info.value)
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    ("text", "canonical"),
    [
        ("W10512", "W105.12"),  # 3 word digits + 2 bit digits
        ("CIO 000100", "CIO1.00"),  # 4 + 2: a bit, not CIO 100
        ("CIO 00100", "CIO100"),  # 5 digits: a word
        ("D0000100", "D1.00"),  # 5 + 2
        ("E2_0000100", "E2_1.00"),
        ("A44800", "A448.00"),
        ("T000100", "T100"),  # timers have no bits: always a number
    ],
)
def test_fixed_width_bit_notation(text: str, canonical: str) -> None:
    assert str(parse_address(text)) == canonical


def test_non_string_is_refused() -> None:
    with pytest.raises(AddressError, match="must be str"):
        parse_address(100)  # type: ignore[arg-type]


def test_out_of_table_designation_formats_raw() -> None:
    assert str(MemoryAddress(0x11, 0x1234, 0x56)) == "#11:1234:56"
    assert str(MemoryAddress(0x82, 0x8000, 0)) == "#82:8000:00"
    assert str(MemoryAddress(0xB0, 0, 1)) == "#B0:0000:01"  # word with a bit: not canonical


def _text_for(spec: AreaSpec, number: int, bit: int) -> MemoryAddress:
    return MemoryAddress(spec.code, spec.first_word + number - spec.first_number, bit)


_SPECS = [spec for spec in AREAS]


@st.composite
def _valid(draw: st.DrawFn) -> tuple[Series, MemoryAddress]:
    spec = draw(st.sampled_from(_SPECS))
    number = draw(st.integers(spec.first_number, spec.last_number))
    bit = draw(st.integers(0, spec.max_bit))
    return spec.series, _text_for(spec, number, bit)


@given(_valid())
def test_every_valid_designation_round_trips_through_text(
    case: tuple[Series, MemoryAddress],
) -> None:
    series, address = case
    text = format_address(address, series)
    assert parse_address(text, series) == address
    assert parse_address(f"  {text.lower()} ", series) == address
    assert format_address(parse_address(text, series), series) == text


@given(_valid())
def test_str_is_canonical_without_a_series(case: tuple[Series, MemoryAddress]) -> None:
    series, address = case
    assert parse_address(str(address), series) == address


_PREFIX_SPELLINGS = {
    "CIO": ["CIO", "cio", "CIO ", ""],
    "W": ["W", "wr", "WR "],
    "H": ["H", "hr"],
    "A": ["A", "ar"],
    "D": ["D", "DM", "dm "],
    "T": ["T", "TIM", "tim "],
    "C": ["C", "CNT"],
}


@given(
    st.sampled_from(sorted(_PREFIX_SPELLINGS)),
    st.integers(0, 99999),
    st.one_of(st.none(), st.integers(0, 15)),
    st.data(),
)
def test_text_parse_str_parse_is_stable(
    area: str, number: int, bit: int | None, data: st.DataObject
) -> None:
    prefix = data.draw(st.sampled_from(_PREFIX_SPELLINGS[area]))
    suffix = ""
    if bit is not None:
        suffix = f".{bit:02d}" if area not in ("T", "C") else ".C"
    text = f"{prefix}{number}{suffix}"
    try:
        first = parse_address(text)
    except AddressError:
        return
    canonical = str(first)
    assert not canonical.startswith("#")
    assert parse_address(canonical) == first
    assert str(parse_address(canonical)) == canonical


@given(st.sampled_from([s for s in _SPECS if not s.alias]), st.integers(1, 70000))
def test_every_out_of_range_number_is_refused(spec: AreaSpec, beyond: int) -> None:
    if spec.data_type in (DataType.FLAG, DataType.BANK_NUMBER):
        return
    same = [
        s
        for s in _SPECS
        if (s.series, s.area, s.data_type, s.bank)
        == (spec.series, spec.area, spec.data_type, spec.bank)
    ]
    number = max(s.last_number for s in same) + beyond
    # digits + 2 digits is the manual's fixed-width bit notation (W10512 = W105.12)
    assume(not spec.digits or len(str(number)) != spec.digits + 2)
    valid = format_address(_text_for(spec, spec.first_number, 0), spec.series)
    head = valid.split(".")[0].rstrip("!").rstrip("0123456789")
    tail = valid[len(head) :].lstrip("0123456789")
    text = f"{head}{number}{tail}"
    with pytest.raises(AddressError, match=r"out of range|does not exist"):
        parse_address(text, spec.series)


@given(st.sampled_from([s for s in _SPECS if s.max_bit]), st.integers(16, 99))
def test_every_out_of_range_bit_is_refused(spec: AreaSpec, bit: int) -> None:
    valid = format_address(_text_for(spec, spec.first_number, 0), spec.series)
    text = valid.replace(".00", f".{bit}")
    with pytest.raises(AddressError, match="bit"):
        parse_address(text, spec.series)


@given(st.text(max_size=20), st.sampled_from([CS, CV]))
def test_arbitrary_text_raises_only_address_error(text: str, series: Series) -> None:
    try:
        address = parse_address(text, series)
    except AddressError:
        return
    check_address(address, series)


@given(
    st.text(alphabet="CIODWHATEMRKP_.!#:0123456789ABFS ", max_size=14), st.sampled_from([CS, CV])
)
def test_address_like_text_raises_only_address_error(text: str, series: Series) -> None:
    try:
        address = parse_address(text, series)
    except AddressError:
        return
    check_address(address, series)
    assert parse_address(format_address(address, series), series) == address


def test_docs_example_runs() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "addresses.md").read_text()
    code = doc.split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(code, "docs/addresses.md", "exec"), {})


def test_parse_span_checks_the_last_element_too() -> None:
    assert parse_span("D32760", 8) == parse_address("D32760")
    assert parse_span("A440", 520) == parse_address("A440")  # A0-A447 and A448-A959: one area
    with pytest.raises(AddressError) as info:
        parse_span("D32760", 9)
    assert info.value.end_code == 0x1104
    assert str(info.value).startswith("'D32760': 9 words from")
    assert "at most 8 from there" in str(info.value)
    with pytest.raises(AddressError, match="'D40000'"):
        parse_span("D40000", 1)  # the start itself: parse_address's error
