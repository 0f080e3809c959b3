"""The virtual PLC's I/O memory, driven with hand-built FINS frames (no sockets)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofins.simulator.memory import IOMemory
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.state import CommandFailed, Mode

HEADER = bytes.fromhex("80 00 02 00 01 00 00 22 00 07")  # to node 1 from node 0x22, SID 07


def call(plc: VirtualPLC, command: str, params: bytes = b"") -> tuple[int, bytes]:
    """Send ``command`` (hex MRC SRC + params) and return (end code, response data)."""
    reply = plc.handle_frame(HEADER + bytes.fromhex(command) + params)
    assert reply is not None
    assert reply[:2] == b"\xc0\x00" and reply[10:12] == bytes.fromhex(command)[:2]
    return int.from_bytes(reply[12:14], "big"), reply[14:]


def read(plc: VirtualPLC, area: int, word: int, bit: int, count: int) -> tuple[int, bytes]:
    return call(plc, "0101", bytes((area, word >> 8, word & 0xFF, bit)) + count.to_bytes(2, "big"))


def write(plc: VirtualPLC, area: int, word: int, bit: int, count: int, data: bytes) -> int:
    params = bytes((area, word >> 8, word & 0xFF, bit)) + count.to_bytes(2, "big") + data
    return call(plc, "0102", params)[0]


@pytest.fixture
def plc() -> VirtualPLC:
    return VirtualPLC(mode=Mode.MONITOR, clock=lambda: 1_700_000_000.0)


def test_word_write_then_read(plc: VirtualPLC) -> None:
    assert write(plc, 0x82, 100, 0, 3, bytes.fromhex("0001 1234 FFFF")) == 0
    assert read(plc, 0x82, 100, 0, 3) == (0, bytes.fromhex("0001 1234 FFFF"))
    assert plc.memory.read_words(0x82, 100, 3) == [1, 0x1234, 0xFFFF]


def test_count_zero_reads_and_writes_nothing(plc: VirtualPLC) -> None:
    assert read(plc, 0x82, 0, 0, 0) == (0, b"")
    assert write(plc, 0x82, 0, 0, 0, b"") == 0
    assert call(plc, "0103", bytes.fromhex("82 0000 00 0000 1234")) == (0, b"")
    assert plc.memory.read_words(0x82, 0, 1) == [0]


@pytest.mark.parametrize(
    ("area", "word", "count", "end_code"),
    [
        (0x82, 32767, 1, 0x0000),
        (0x82, 32767, 2, 0x1104),  # end past D32767
        (0x82, 32768, 1, 0x1103),  # start outside DM
        (0xB0, 6143, 2, 0x1104),
        (0xB0, 6144, 1, 0x1103),
        (0xB1, 511, 2, 0x1104),
        (0xB2, 512, 1, 0x1103),
        (0xB3, 959, 2, 0x1104),
        (0x89, 4095, 2, 0x1104),  # timers do not run on into counters
        (0x89, 0x8FFF, 1, 0x0000),
        (0x89, 0x1000, 1, 0x1103),
        (0xA3, 32760, 9, 0x1104),
        (0x68, 0, 1, 0x0000),  # EM bank 18 hex (24)
        (0x77, 0, 1, 0x1101),  # no such area code
    ],
)
def test_address_ranges(plc: VirtualPLC, area: int, word: int, count: int, end_code: int) -> None:
    code, data = read(plc, area, word, 0, count)
    assert code == end_code
    assert len(data) == (2 * count if end_code == 0 else 0)


def test_bit_range_and_bit_number(plc: VirtualPLC) -> None:
    assert read(plc, 0x30, 6143, 15, 1) == (0, b"\x00")
    assert read(plc, 0x30, 6143, 15, 2)[0] == 0x1104
    assert read(plc, 0x30, 0, 16, 1)[0] == 0x1103
    assert read(plc, 0x82, 0, 1, 1)[0] == 0x1103  # a word address has bit 00


def test_bit_and_word_views_agree(plc: VirtualPLC) -> None:
    assert write(plc, 0x30, 10, 13, 1, b"\x01") == 0  # CIO 10.13
    assert read(plc, 0xB0, 10, 0, 1) == (0, b"\x20\x00")
    assert write(plc, 0x82, 5, 0, 1, b"\x80\x01") == 0
    assert read(plc, 0x02, 5, 0, 16) == (0, bytes([1] + [0] * 14 + [1]))
    # a bit run crosses into the next word
    assert write(plc, 0x31, 3, 14, 4, b"\x01\x01\x01\x01") == 0
    assert plc.memory.read_words(0xB1, 3, 2) == [0xC000, 0x0003]
    assert plc.memory.read_bits(0x31, 3, 14, 4) == [True] * 4


def test_bit_data_must_be_0_or_1(plc: VirtualPLC) -> None:
    assert write(plc, 0x30, 0, 0, 1, b"\x02") == 0x110C


def test_data_length_must_match_count(plc: VirtualPLC) -> None:
    assert write(plc, 0x82, 0, 0, 2, b"\x00\x01") == 0x1003


def test_auxiliary_area_read_only_part(plc: VirtualPLC) -> None:
    assert write(plc, 0xB3, 447, 0, 1, b"\x00\x01") == 0x2101
    assert write(plc, 0xB3, 440, 0, 10, bytes(20)) == 0x2101
    assert write(plc, 0x33, 447, 15, 1, b"\x01") == 0x2101
    assert write(plc, 0xB3, 448, 0, 1, b"\x12\x34") == 0
    assert read(plc, 0xB3, 448, 0, 1) == (0, b"\x12\x34")
    assert read(plc, 0xB3, 0, 0, 448)[0] == 0
    assert call(plc, "0103", bytes.fromhex("B3 0000 00 0001 FFFF"))[0] == 0x2101
    assert call(plc, "0105", bytes.fromhex("82 000000 B3 000000 0001"))[0] == 0x2101


def test_em_banks_and_current_bank(plc: VirtualPLC) -> None:
    assert write(plc, 0xA3, 10, 0, 1, b"\xbe\xef") == 0  # E3_10
    # 01 02 cannot write the bank number (manual 5-3-3); the program's EMBC does, here:
    assert write(plc, 0xBC, 0x0F00, 0, 1, b"\x00\x03") == 0x1101
    plc.write("EMBANK", [3])  # current bank ← 3
    assert read(plc, 0x98, 10, 0, 1) == (0, b"\xbe\xef")
    assert read(plc, 0xBC, 0x0F00, 0, 1) == (0, b"\x00\x03")
    assert read(plc, 0x53, 10, 0, 1) == (0, b"\xbe\xef")  # CJ2 alias of bank 3
    assert read(plc, 0x23, 10, 0, 16)[1][:2] == b"\x01\x01"  # E3 bits view
    assert write(plc, 0x64, 0, 0, 1, b"\x00\x07") == 0  # E14_0 (bank 14 hex)
    with pytest.raises(CommandFailed, match="EM bank 25 absent") as info:
        plc.write("EMBANK", [0x19])
    assert info.value.end_code == 0x110C


def test_absent_em_bank_is_area_missing() -> None:
    small = VirtualPLC(em_banks=4)
    assert read(small, 0xA3, 0, 0, 1)[0] == 0
    assert read(small, 0xA4, 0, 0, 1)[0] == 0x1101
    assert read(small, 0x60, 0, 0, 1)[0] == 0x1101


def test_no_em_at_all() -> None:
    plc = VirtualPLC(em_banks=0)
    assert read(plc, 0x98, 0, 0, 1)[0] == 0x1101
    assert read(plc, 0x0A, 0, 0, 1)[0] == 0x1101
    assert read(plc, 0xA0, 0, 0, 1)[0] == 0x1101


def test_timer_counter_pv_and_completion_flags(plc: VirtualPLC) -> None:
    plc.memory.set_completion(5, True)
    plc.memory.set_completion(5, True, counter=True)
    assert write(plc, 0x89, 5, 0, 1, b"\x01\x00") == 0  # 0102 keeps the completion flag
    assert read(plc, 0x09, 5, 0, 1) == (0, b"\x01")
    assert write(plc, 0x89, 0x8005, 0, 1, b"\x02\x00") == 0  # counter C5
    assert read(plc, 0x89, 0x8005, 0, 1) == (0, b"\x02\x00")
    assert read(plc, 0x89, 5, 0, 1) == (0, b"\x01\x00")
    assert call(plc, "0103", bytes.fromhex("89 0005 00 0001 0000"))[0] == 0
    assert read(plc, 0x09, 5, 0, 1) == (0, b"\x00")  # 0103 turns it OFF
    assert read(plc, 0x09, 0x8005, 0, 1) == (0, b"\x01")
    assert write(plc, 0x09, 5, 0, 1, b"\x01") == 0x1101  # flags are not writable by 0102


def test_fill_and_transfer(plc: VirtualPLC) -> None:
    assert call(plc, "0103", bytes.fromhex("82 0010 00 0004 ABCD")) == (0, b"")
    assert plc.memory.read_words(0x82, 16, 5) == [0xABCD] * 4 + [0]
    assert call(plc, "0105", bytes.fromhex("82 001000 B1 000000 0004")) == (0, b"")
    assert plc.memory.read_words(0xB1, 0, 4) == [0xABCD] * 4
    assert call(plc, "0105", bytes.fromhex("82 7FFF00 B1 000000 0002"))[0] == 0x1104
    assert call(plc, "0103", bytes.fromhex("30 0000 00 0001 0001"))[0] == 0x1101


def test_multiple_memory_area_read(plc: VirtualPLC) -> None:
    plc.memory.write_words(0x82, 0, [0x1234])
    plc.memory.write_bits(0x30, 1, 2, [True])
    plc.memory.write_words(0xDC, 0x0100, [0x00010002])
    params = bytes.fromhex("82000000 30000102 DC010000 07100F00 F0000100")
    code, data = call(plc, "0104", params)
    assert code == 0
    assert data == bytes.fromhex("82 1234 30 01 DC 00010002 07 01 F0 0000 0004")
    assert call(plc, "0104", b"") == (0, b"")
    assert call(plc, "0104", bytes.fromhex("82000000 82800000"))[0] == 0x1103  # nothing read
    assert call(plc, "0104", bytes.fromhex("820000"))[0] == 0x1002


def test_forced_set_reset_keeps_bits(plc: VirtualPLC) -> None:
    # force CIO 0.00 ON and W1.03 OFF
    entries = bytes.fromhex("0001 30 0000 00  0000 31 0001 03")
    assert call(plc, "2301", b"\x00\x02" + entries) == (0, b"")
    assert write(plc, 0xB0, 0, 0, 1, b"\x00\x00") == 0
    assert write(plc, 0xB1, 1, 0, 1, b"\xff\xff") == 0
    assert plc.memory.read_words(0xB0, 0, 1) == [0x0001]
    assert plc.memory.read_words(0xB1, 1, 1) == [0xFFF7]
    assert call(plc, "0104", bytes.fromhex("70000000 F0000000 71000103")) == (
        0,
        bytes.fromhex("70 03 F0 0001 0001 71 02"),
    )
    assert plc.memory.forced_count() == 2
    assert call(plc, "2302") == (0, b"")
    assert plc.memory.forced_count() == 0
    assert write(plc, 0xB0, 0, 0, 1, b"\x00\x00") == 0
    assert plc.memory.read_words(0xB0, 0, 1) == [0]


def test_forced_release_codes(plc: VirtualPLC) -> None:
    assert call(plc, "2301", bytes.fromhex("0001 0001 32 0002 05"))[0] == 0
    assert call(plc, "2301", bytes.fromhex("0001 FFFF 32 0002 05"))[0] == 0  # keep ON
    assert plc.memory.read_bits(0x32, 2, 5, 1) == [True]
    assert plc.memory.forced_count() == 0
    assert call(plc, "2301", bytes.fromhex("0001 8000 32 0002 05"))[0] == 0  # OFF
    assert plc.memory.read_bits(0x32, 2, 5, 1) == [False]
    assert call(plc, "2301", bytes.fromhex("0001 0001 09 0003 00"))[0] == 0  # T3 flag
    assert read(plc, 0x09, 3, 0, 1) == (0, b"\x01")
    assert call(plc, "2301", bytes.fromhex("0001 1234 30 0000 00"))[0] == 0x110C
    assert call(plc, "2301", bytes.fromhex("0001 0001 82 0000 00"))[0] == 0x1101
    # fewer entries than counted: the codec answers 1002 (command too short)
    assert call(plc, "2301", bytes.fromhex("0002 0001 30 0000 00"))[0] == 0x1002


def test_system_flags_and_registers() -> None:
    t = [0.0]
    plc = VirtualPLC(clock=lambda: t[0])
    assert read(plc, 0x07, 0x100F, 0, 1) == (0, b"\x01")  # Always ON
    assert read(plc, 0x07, 0x100E, 0, 1) == (0, b"\x00")  # Always OFF
    assert read(plc, 0x07, 0x0001, 0, 1) == (0, b"\x01")  # 1 s pulse, first half
    t[0] = 0.75
    assert read(plc, 0x07, 0x0001, 0, 1) == (0, b"\x00")
    assert write(plc, 0xDC, 0x0100, 0, 2, bytes.fromhex("DEADBEEF 00000001")) == 0
    assert read(plc, 0xDC, 0x0101, 0, 1) == (0, bytes.fromhex("00000001"))
    assert write(plc, 0xBC, 0x0203, 0, 1, b"\x00\x09") == 0  # DR3
    assert read(plc, 0xBC, 0x0203, 0, 1) == (0, b"\x00\x09")
    assert read(plc, 0x06, 0x0000, 0, 32) == (0, bytes(32))  # PROGRAM mode: task 0 idle
    plc.mode = Mode.RUN
    assert read(plc, 0x06, 0x0000, 0, 2) == (0, b"\x01\x00")
    assert read(plc, 0x46, 0x0000, 0, 1) == (0, b"\x01")
    assert write(plc, 0x07, 0x100F, 0, 1, b"\x00") == 0x1101


def test_iomemory_rejects_bad_bank_count() -> None:
    with pytest.raises(ValueError):
        IOMemory(em_banks=26)
    with pytest.raises(CommandFailed) as info:
        IOMemory(em_banks=1).read_words(0xA1, 0, 1)
    assert info.value.end_code == 0x1101


@settings(max_examples=60, deadline=None)
@given(
    word=st.integers(0, 32767),
    values=st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=40),
)
def test_word_round_trip(word: int, values: list[int]) -> None:
    plc = VirtualPLC()
    data = b"".join(v.to_bytes(2, "big") for v in values)
    expected = 0 if word + len(values) <= 32768 else 0x1104
    assert write(plc, 0x82, word, 0, len(values), data) == expected
    if expected == 0:
        assert read(plc, 0x82, word, 0, len(values)) == (0, data)
        bits = read(plc, 0x02, word, 0, 16 * len(values))[1]
        assert bits == bytes((v >> b) & 1 for v in values for b in range(16))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_arbitrary_frames_never_raise(raw: bytes) -> None:
    plc = VirtualPLC()
    plc.handle_frame(raw)
    reply = plc.handle_frame(HEADER + raw)
    if reply is not None:
        assert reply[0] == 0xC0 and reply[9] == 0x07


@settings(max_examples=300, deadline=None)
@given(
    area=st.integers(0, 255),
    word=st.integers(0, 0xFFFF),
    bit=st.integers(0, 255),
    count=st.integers(0, 40),
    write=st.booleans(),
)
def test_any_address_gets_an_end_code(
    area: int, word: int, bit: int, count: int, write: bool
) -> None:
    plc = VirtualPLC(em_banks=4)
    head = bytes((area, word >> 8, word & 0xFF, bit)) + count.to_bytes(2, "big")
    if write:
        size = {0xDC: 4}.get(area, 2 if area >= 0x80 or 0x50 <= area <= 0x68 else 1)
        code, data = call(plc, "0102", head + bytes(size * count))
        assert data == b""
    else:
        code, data = call(plc, "0101", head)
        if code != 0:
            assert data == b""  # an error reads nothing
    assert code in {0, 0x1001, 0x1003, 0x1101, 0x1103, 0x1104, 0x110B, 0x110C, 0x2101}


@settings(max_examples=60, deadline=None)
@given(
    start=st.integers(0, 6144 * 16 - 1),
    bits=st.lists(st.integers(0, 1), min_size=1, max_size=600),
    forced=st.sets(st.integers(0, 6144 * 16 - 1), max_size=20),
    seed=st.lists(st.integers(0, 0xFFFF), min_size=40, max_size=40),
)
def test_bit_runs_match_the_per_bit_definition(
    start: int, bits: list[int], forced: set[int], seed: list[int]
) -> None:
    """Reads and writes of CIO bits (area 30) go word-wise; they must agree with the
    element-by-element definition (``_get``/``_set``), forced bits included."""
    start = min(start, 6144 * 16 - len(bits))
    fast, slow = IOMemory(em_banks=0), IOMemory(em_banks=0)
    first = start // 16
    for memory in (fast, slow):
        memory.write_words(0xB0, min(first, 6144 - 40), seed)
        for i in forced:
            memory.force(0x30, i // 16, i % 16, 0x0001)
    area = slow.area(0x30)
    word, bit = divmod(start, 16)
    expected = bytes(slow._get(area, i) for i in range(start, start + len(bits)))
    assert fast.read(0x30, word, bit, len(bits), frozenset({0x30})) == expected
    assert fast.read_bits(0x30, word, bit, len(bits)) == [b == 1 for b in expected]
    fast.write(0x30, word, bit, bytes(bits), len(bits), frozenset({0x30}))
    for j, v in enumerate(bits):
        slow._set(area, start + j, v)
    assert fast._stores["CIO"] == slow._stores["CIO"]
    near = min(first, 6141)
    assert fast.read_words(0xB0, near, 3) == slow.read_words(0xB0, near, 3)
