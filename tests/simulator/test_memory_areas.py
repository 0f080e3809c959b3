"""The virtual PLC's area map agrees with the protocol's table of manual 5-2-2 (CS/CJ)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofins.protocol.areas import (
    FLAGS,
    MemoryAddress,
    Series,
    area_codes,
    area_specs,
    check_address,
    check_span,
)
from aiofins.protocol.errors import AddressError
from aiofins.protocol.header import FinsAddress, build_command
from aiofins.simulator.memory import (
    AREAS,
    FILL_AREAS,
    MULTIPLE_READ_AREAS,
    WRITE_AREAS,
    IOMemory,
)
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.state import CommandFailed

from .test_memory import read

CS_CJ_CODES = sorted(area_codes(Series.CS_CJ))


def accepts(memory: IOMemory, code: int, word: int, bit: int = 0, count: int = 1) -> int:
    """End code of locating ``count`` elements at ``code``/``word``/``bit`` (0 = accepted)."""
    try:
        memory.locate(memory.area(code), word, bit, count)
    except CommandFailed as exc:
        return exc.end_code
    return 0


def test_same_area_codes_as_the_protocol() -> None:
    assert sorted(AREAS) == CS_CJ_CODES
    for allowed in (MULTIPLE_READ_AREAS, WRITE_AREAS, FILL_AREAS):
        assert set(AREAS) >= allowed


@pytest.mark.parametrize("code", CS_CJ_CODES, ids=lambda c: f"{c:02X}")
def test_every_row_has_the_same_word_range(code: int) -> None:
    memory = IOMemory(em_banks=25)
    specs = area_specs(code)
    area = AREAS[code]
    assert {s.element_size for s in specs} == {area.element_size}
    assert area.elements == sum(s.count for s in specs)
    for spec in specs:
        assert accepts(memory, code, spec.first_word, spec.max_bit) == 0, spec.describe()
        assert accepts(memory, code, spec.last_word, spec.max_bit) == 0, spec.describe()
        assert accepts(memory, code, spec.first_word, spec.max_bit + 1) == 0x1103
        for outside in (spec.first_word - 1, spec.last_word + 1):
            if 0 <= outside <= 0xFFFF:
                inside = any(s.contains(outside) for s in specs)
                assert accepts(memory, code, outside) == (0 if inside else 0x1103), hex(outside)


def test_area_07_flag_words_agree_with_the_manual() -> None:
    memory = IOMemory()
    flag_words = {word for word, _, _ in FLAGS}
    accepted = {w for w in range(0x10000) if accepts(memory, 0x07, w) == 0}
    assert accepted == flag_words
    # Manual 5-2-2 lists 100A00 (Less Than or Equals) then 100E00: no 100B-100D.
    for word in (0x100B, 0x100C, 0x100D):
        assert word not in flag_words
        assert accepts(memory, 0x07, word) == 0x1103
    assert accepts(memory, 0x07, 0x1000, count=11) == 0  # P_ER .. P_LE
    assert accepts(memory, 0x07, 0x1000, count=12) == 0x1104  # would run into 100B
    assert accepts(memory, 0x07, 0x100E, count=2) == 0  # Always OFF, Always ON


def test_condition_flags_read_through_area_07() -> None:
    plc = VirtualPLC(clock=lambda: 0.0)
    plc.memory.set_condition_flag("P_CY", True)
    plc.memory.set_condition_flag("P_AER", True)
    assert read(plc, 0x07, 0x1000, 0, 4) == (0, bytes.fromhex("00 01 00 00"))
    assert read(plc, 0x07, 0x2001, 0, 1) == (0, b"\x01")
    assert read(plc, 0x07, 0x100E, 0, 2) == (0, b"\x00\x01")  # Always OFF, Always ON
    assert read(plc, 0x07, 0x0000, 0, 5) == (0, bytes([1] * 5))  # pulses, first half
    assert read(plc, 0x07, 0x100B, 0, 1) == (0x1103, b"")
    with pytest.raises(ValueError):
        plc.memory.set_condition_flag("P_On", False)
    with pytest.raises(ValueError):
        plc.memory.set_condition_flag("P_1s", True)


@settings(max_examples=400, deadline=None)
@given(
    code=st.sampled_from(CS_CJ_CODES),
    word=st.one_of(st.integers(0, 0xFFFF), st.sampled_from([0, 0x100B, 0x1000, 0x8FFF, 0x0F00])),
    bit=st.integers(0, 0x1F),
)
def test_accepts_exactly_what_the_protocol_accepts(code: int, word: int, bit: int) -> None:
    memory = IOMemory(em_banks=25)
    try:
        check_address(MemoryAddress(code, word, bit), Series.CS_CJ)
        valid = True
    except AddressError:
        valid = False
    end_code = accepts(memory, code, word, bit)
    assert end_code in (0, 0x1103)
    assert (end_code == 0) == valid


@st.composite
def spans(draw: st.DrawFn) -> tuple[int, int, int, int]:
    """A valid start (code, word, bit) and a count around the room its area has left."""
    code = draw(st.sampled_from(CS_CJ_CODES))
    spec = draw(st.sampled_from(area_specs(code)))
    word = draw(
        st.sampled_from([spec.first_word, spec.last_word])
        | st.integers(spec.first_word, spec.last_word)
    )
    bit = draw(st.integers(0, spec.max_bit))
    room = sum(s.count for s in area_specs(code)) * (16 if spec.max_bit else 1)
    count = draw(st.integers(1, 4) | st.integers(1, room + 2))
    return code, word, bit, count


@settings(max_examples=400, deadline=None)
@given(spans())
def test_span_refused_exactly_where_the_plc_answers_1104(span: tuple[int, int, int, int]) -> None:
    """check_span (the client's check before sending) agrees with the virtual PLC's 1104."""
    code, word, bit, count = span
    memory = IOMemory(em_banks=25)
    address = MemoryAddress(code, word, bit)
    try:
        check_span(address, count, Series.CS_CJ)
        refused = None
    except AddressError as exc:
        refused = exc.end_code
    end_code = accepts(memory, code, word, bit, count)
    assert end_code in (0, 0x1104)
    assert refused == (end_code or None)


# -- an NJ/NX CPU: FINS reaches only AT-mapped memory ------------------------------------------


def _nj() -> VirtualPLC:
    return VirtualPLC(model="NJ501-1300", at_mapped=[("D100", 10), ("E3_0", 4), ("W0", 1)])


def _answer(plc: VirtualPLC, mrc: int, src: int, params: bytes) -> int:
    frame = build_command(FinsAddress(0, 1, 0), FinsAddress(0, 2, 0), 1, mrc, src, params)
    reply = plc.handle_frame(frame)
    assert reply is not None
    return int.from_bytes(reply[12:14], "big")


@pytest.mark.parametrize(
    ("params", "end_code"),
    [
        ("82006400000a", 0x0000),  # D100..D109: mapped
        ("82006d000001", 0x0000),  # D109
        ("82006d000002", 0x1101),  # D109..D110: runs past the mapping
        ("820063000001", 0x1101),  # D99
        ("a30000000004", 0x0000),  # E3_0..E3_3
        ("a20000000001", 0x1101),  # E2_0: another bank
        ("b10000000001", 0x0000),  # W0
        ("3100000f0001", 0x0000),  # W0.15, a bit of a mapped word
        ("310001000001", 0x1101),  # W1.00
        ("b00000000001", 0x1101),  # CIO 0
    ],
)
def test_an_nj_answers_unmapped_memory_with_1101(params: str, end_code: int) -> None:
    assert _answer(_nj(), 0x01, 0x01, bytes.fromhex(params)) == end_code


def test_an_nj_refuses_writes_and_transfers_touching_unmapped_memory() -> None:
    plc = _nj()
    assert _answer(plc, 0x01, 0x02, bytes.fromhex("820064000001BEEF")) == 0
    assert plc.read("D100") == [0xBEEF]
    assert _answer(plc, 0x01, 0x02, bytes.fromhex("820000000001BEEF")) == 0x1101
    assert plc.read("D0") == [0]
    # 0104 with one unmapped item, 0105 into unmapped memory
    assert _answer(plc, 0x01, 0x04, bytes.fromhex("8200640082000000")) == 0x1101
    assert _answer(plc, 0x01, 0x05, bytes.fromhex("82006400820000000001")) == 0x1101
    assert _answer(plc, 0x01, 0x04, bytes.fromhex("82006400b1000000")) == 0
    # a CS/CJ (no at_mapped) reads all of it
    assert _answer(VirtualPLC(), 0x01, 0x01, bytes.fromhex("820000000001")) == 0
