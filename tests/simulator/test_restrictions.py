"""Execution conditions (manual 5-1-2): every command x every condition → the manual's end code."""

from __future__ import annotations

import pytest

from aiofins.protocol.header import FinsAddress
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.restrictions import (
    MODE_END_CODES,
    RESTRICTIONS,
    Restriction,
    is_write_command,
    restriction_for,
)
from aiofins.simulator.state import Mode

HEADER = bytes.fromhex("80 00 02 00 01 00 00 22 00 31")  # to node 1 from node 0x22, SID 31
NAME = b"DATA    .BIN"
NAME2 = b"COPY    .BIN"

# The 5-1-2 table as printed (RUN MONITOR PROGRAM access UM-read DIP network), one line each;
# "-" is the blank cell of 0702. A cell ending in "!" is where the rest of the manual
# overrides 5-1-2: 2103's access right (5-3-29 and the access-right lists of 5-3-24/25 say
# No; 5-1-2 says OK).
MANUAL_5_1_2 = """
0101 OK OK OK OK OK OK OK
0102 OK OK OK OK OK OK NO
0103 OK OK OK OK OK OK NO
0104 OK OK OK OK OK OK OK
0105 OK OK OK OK OK OK NO
0201 OK OK OK OK OK OK OK
0202 OK OK OK NO OK NO NO
0203 OK OK OK NO OK NO NO
0306 OK OK OK OK NO OK OK
0307 NO NO OK NO OK NO NO
0308 NO NO OK NO OK NO NO
0401 OK OK OK NO OK OK NO
0402 OK OK OK NO OK OK NO
0501 OK OK OK OK OK OK OK
0502 OK OK OK OK OK OK OK
0601 OK OK OK OK OK OK OK
0620 OK OK NO OK OK OK OK
0701 OK OK OK OK OK OK OK
0702 OK OK OK NO OK OK -
0C01 OK OK OK NO OK OK NO
0C02 OK OK OK OK OK OK OK
0C03 OK OK OK OK OK OK OK
2101 OK OK OK NO OK OK NO
2102 OK OK OK OK OK OK OK
2103 OK OK OK NO! OK OK NO
2140 OK OK OK OK OK OK OK
2141 OK OK OK NO OK OK NO
2201 OK OK OK OK OK OK OK
2202 OK OK OK OK OK OK OK
2203 OK OK OK NO OK OK NO
2204 OK OK OK NO OK OK NO
2205 OK OK OK NO OK OK NO
2207 OK OK OK NO OK OK NO
2208 OK OK OK NO OK OK NO
220A OK OK OK NO OK OK NO
2215 OK OK OK NO OK OK NO
2220 NO NO OK NO OK OK NO
2301 NO OK OK OK OK OK NO
2302 NO OK OK OK OK OK NO
2803 OK OK OK OK OK OK OK
2804 OK OK OK OK OK OK OK
2805 OK OK OK OK OK OK OK
"""


def _manual_rows() -> dict[int, list[str]]:
    rows = {}
    for line in MANUAL_5_1_2.strip().splitlines():
        code, *cells = line.split()
        rows[int(code, 16)] = cells
    return rows


@pytest.mark.parametrize(("code", "cells"), sorted(_manual_rows().items()))
def test_table_matches_the_manual(code: int, cells: list[str]) -> None:
    row = RESTRICTIONS[code]
    got = [row.run, row.monitor, row.program, row.access_right, row.um_read, row.dip_write]
    got.append(row.network_write)
    for cell, value in zip(cells, got, strict=True):
        if cell == "-":  # 0702's blank cell: refused, per 5-1-1 note 1 and 5-3-20
            assert value is False
        elif cell.endswith("!"):  # overridden by the command's own table
            assert value is (cell[:-1] == "OK")
        else:
            assert value is (cell == "OK")


def test_variant_rows() -> None:
    # 0920: only MESSAGE CLEAR is refused while another node holds the access right
    assert restriction_for(0x0920, b"\x00\x01") == RESTRICTIONS[(0x0920, "read")]
    assert not restriction_for(0x0920, b"\x40\x01").access_right  # type: ignore[union-attr]
    assert restriction_for(0x0920, b"\x80\x01").access_right  # type: ignore[union-attr]
    # 220B/220C notes: file → area transfers are refused in RUN and MONITOR
    from_file = restriction_for(0x220C, b"\x00\x01")
    assert from_file is not None and not from_file.run and not from_file.monitor
    to_file = restriction_for(0x220C, b"\x00\x00")
    assert to_file is not None and to_file.run and to_file.dip_write
    # 220C under DIP-switch protection: only program-to-file (note 3; 5-3-41 note 1)
    compare = restriction_for(0x220C, b"\x00\x02")
    assert compare is not None and compare.run and not compare.dip_write
    # 0920 under network write protection: OK for every variant (5-1-1 note 1, 5-3-21..23)
    for params in (b"\x00\x01", b"\x40\x01", b"\x80\x01"):
        row = restriction_for(0x0920, params)
        assert row is not None and row.network_write
    assert not is_write_command(0x0920, b"\x40\x01")
    assert restriction_for(0x9999) is None
    assert is_write_command(0x0102) and not is_write_command(0x0101)


# A well-formed command for every row (the codec accepts each).
SAMPLES: dict[int | tuple[int, str], str | bytes] = {
    0x0101: "82 0000 00 0001",
    0x0102: "82 0000 00 0001 0000",
    0x0103: "82 0000 00 0001 0000",
    0x0104: "82 0000 00",
    0x0105: "82 000000 82 000100 0001",
    0x0201: "8010 0000 0001",
    0x0202: "8010 0000 0001 0000",
    0x0203: "8010 0000 0200 0000",
    0x0306: "FFFF 00000000 0004",
    0x0307: "FFFF 00000000 8004 00000000",
    0x0308: "FFFF 00",
    0x0401: "FFFF 04",
    0x0402: "FFFF",
    0x0501: "",
    0x0502: "00 19",
    0x0601: "",
    0x0620: "01",
    0x0701: "",
    0x0702: "24 01 02 03 04 05",
    (0x0920, "read"): "0001",
    (0x0920, "clear"): "4001",
    (0x0920, "fal"): "8001",
    0x0C01: "FFFF",
    0x0C02: "FFFF",
    0x0C03: "FFFF",
    0x2101: "FFFE",
    0x2102: "0000 0000",
    0x2103: "",
    0x2140: "0000 0000",
    0x2141: "",
    0x2201: "8000 0000 0000 0000",
    0x2202: b"\x80\x00" + NAME + bytes.fromhex("00000000 0000 0000"),
    0x2203: b"\x80\x00\x00\x01" + NAME + bytes.fromhex("00000000 0002 AABB 0000"),
    0x2204: "8000",
    0x2205: b"\x80\x00\x00\x01" + NAME + b"\x00\x00",
    0x2207: b"\x80\x00" + NAME + b"\x80\x01" + NAME2 + b"\x00\x00\x00\x00",
    0x2208: b"\x80\x00" + NAME + NAME2 + b"\x00\x00",
    0x220A: b"\x00\x00\x82\x00\x00\x00\x00\x01\x80\x00" + NAME + b"\x00\x00",
    (0x220B, "to_file"): bytes.fromhex("0000 8010 0000 FFFF 8000") + NAME + b"\x00\x00",
    (0x220B, "from_file"): bytes.fromhex("0001 8010 0000 FFFF 8000") + NAME + b"\x00\x00",
    (0x220B, "compare"): bytes.fromhex("0002 8010 0000 FFFF 8000") + NAME + b"\x00\x00",
    (0x220C, "to_file"): bytes.fromhex("0000 FFFF 00000000 FFFFFFFF 8000") + NAME + b"\x00\x00",
    (0x220C, "from_file"): bytes.fromhex("0001 FFFF 00000000 FFFFFFFF 8000") + NAME + bytes(2),
    (0x220C, "compare"): bytes.fromhex("0002 FFFF 00000000 FFFFFFFF 8000") + NAME + b"\x00\x00",
    0x2215: b"\x80\x00\x00\x00" + b"SUB         " + b"\x00\x00",
    0x2301: "0001 0001 30 0000 00",
    0x2302: "",
    0x2803: b"00000" + b"0501",
    0x2804: "01 03 0000 0001",
    0x2805: b"0103" + b"00000001",
}
CONDITIONS = ("run", "monitor", "program", "access_right", "um_read", "dip_write", "network")
RESTRICTION_CODES = {0x2102, 0x3001, 0x2002, 0x2101, *MODE_END_CODES.values()}


def _params(key: int | tuple[int, str]) -> bytes:
    sample = SAMPLES[key]
    return bytes.fromhex(sample) if isinstance(sample, str) else sample


def _baseline(row: Restriction) -> Mode:
    return Mode.PROGRAM if row.program else Mode.MONITOR


def _plc_in(condition: str, row: Restriction) -> VirtualPLC:
    modes = {"run": Mode.RUN, "monitor": Mode.MONITOR, "program": Mode.PROGRAM}
    plc = VirtualPLC(
        mode=modes.get(condition, _baseline(row)),
        um_read_protected=condition == "um_read",
        um_write_protected=condition == "dip_write",
        network_write_protection=condition == "network",
        clock=lambda: 1_700_000_000.0,
    )
    if condition == "access_right":
        plc.access_holder = FinsAddress(0, 0x63, 0)
    return plc


def _expected(condition: str, row: Restriction) -> int | None:
    """The refusing end code, or None when the command must not be refused."""
    allowed = {
        "run": row.run,
        "monitor": row.monitor,
        "program": row.program,
        "access_right": row.access_right,
        "um_read": row.um_read,
        "dip_write": row.dip_write,
        "network": row.network_write,
    }[condition]
    if allowed:
        return None
    return {
        "run": MODE_END_CODES[Mode.RUN],
        "monitor": MODE_END_CODES[Mode.MONITOR],
        "program": MODE_END_CODES[Mode.PROGRAM],
        "access_right": 0x3001,
        "um_read": 0x2002,
        "dip_write": 0x2101,
        "network": 0x2102,
    }[condition]


CASES = [
    pytest.param(
        key,
        condition,
        id=f"{key if isinstance(key, int) else key[0]:04X}"
        f"{'' if isinstance(key, int) else '-' + key[1]}-{condition}",
    )
    for key in SAMPLES
    for condition in CONDITIONS
]


@pytest.mark.parametrize(("key", "condition"), CASES)
def test_every_command_under_every_condition(key: int | tuple[int, str], condition: str) -> None:
    code = key if isinstance(key, int) else key[0]
    row = RESTRICTIONS[key]
    plc = _plc_in(condition, row)
    frame = HEADER + code.to_bytes(2, "big") + _params(key)
    reply = plc.handle_frame(frame)
    assert reply is not None
    end_code = int.from_bytes(reply[12:14], "big") & 0x7F3F
    expected = _expected(condition, row)
    if expected is None:
        assert end_code not in RESTRICTION_CODES, f"refused with {end_code:04X}"
    else:
        assert end_code == expected
        if code == 0x0C01 and condition == "access_right":
            assert reply[14:] == bytes((0, 0x63, 0))  # the holder: network, node, unit
        else:
            assert reply[14:] == b""


def test_refused_commands_change_nothing() -> None:
    plc = VirtualPLC(network_write_protection=True)
    assert plc.handle_frame(HEADER + bytes.fromhex("0102 82000000 0001 1234"))[12:14] == b"\x21\x02"  # type: ignore[index]
    assert plc.memory.read_words(0x82, 0, 1) == [0]


def test_network_write_protection_allows_listed_nodes() -> None:
    plc = VirtualPLC(network_write_protection=True, write_allowed_nodes=[(0, 0x22)])
    reply = plc.handle_frame(HEADER + bytes.fromhex("0102 82000000 0001 1234"))
    assert reply is not None and reply[12:14] == b"\x00\x00"
    assert plc.memory.read_words(0x82, 0, 1) == [0x1234]


def test_serial_port_frames_are_not_network_write_protected() -> None:
    plc = VirtualPLC(network_write_protection=True)
    frame = HEADER + bytes.fromhex("0102 82000000 0001 1234")
    reply = plc.handle_frame(frame, from_network=False)
    assert reply is not None and reply[12:14] == b"\x00\x00"


def test_access_right_holder_itself_is_not_refused() -> None:
    plc = VirtualPLC(mode=Mode.PROGRAM)
    plc.access_holder = FinsAddress(0, 0x22, 0)
    reply = plc.handle_frame(HEADER + bytes.fromhex("0402 FFFF"))
    assert reply is not None and reply[12:14] == b"\x00\x00"


def test_memory_cassette_transfer_is_not_supported_by_a_cj2m() -> None:
    reply = VirtualPLC().handle_frame(HEADER + bytes.fromhex("2220 8003 0000 0001"))
    assert reply is not None and reply[12:14] == b"\x04\x01"
