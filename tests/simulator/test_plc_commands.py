"""The virtual PLC's command dispatch and command semantics, with hand-built frames."""

from __future__ import annotations

from datetime import datetime

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiofins.protocol.commands import decode_request, encode_result
from aiofins.protocol.header import FinsAddress
from aiofins.simulator.handlers import HANDLERS
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.state import Mode

T0 = datetime(2024, 3, 5, 10, 20, 30).timestamp()  # a Tuesday


def frame(
    command: str,
    params: bytes = b"",
    *,
    sid: int = 0x11,
    node: int = 0x22,
    dest: tuple[int, int, int] = (0, 1, 0),
    icf: int = 0x80,
) -> bytes:
    net, dnode, unit = dest
    header = bytes((icf, 0x00, 0x02, net, dnode, unit, 0x00, node, 0x00, sid))
    return header + bytes.fromhex(command) + params


def call(plc: VirtualPLC, command: str, params: bytes | str = b"", **kw: int) -> tuple[int, bytes]:
    raw = bytes.fromhex(params) if isinstance(params, str) else params
    reply = plc.handle_frame(frame(command, raw, **kw))  # type: ignore[arg-type]
    assert reply is not None
    return int.from_bytes(reply[12:14], "big"), reply[14:]


@pytest.fixture
def plc() -> VirtualPLC:
    return VirtualPLC(mode=Mode.PROGRAM, clock=lambda: T0)


# ---- addressing ----------------------------------------------------------------------------


def test_response_header_swaps_addresses_and_echoes_sid(plc: VirtualPLC) -> None:
    reply = plc.handle_frame(frame("0101", bytes.fromhex("82000000 0001"), sid=0x5A))
    assert reply == bytes.fromhex("C0 00 02 00 22 00 00 01 00 5A 0101 0000 0000")


def test_frames_for_other_nodes_are_ignored(plc: VirtualPLC) -> None:
    assert plc.handle_frame(frame("0601", dest=(0, 2, 0))) is None
    assert plc.frames_ignored == 1 and plc.frames_handled == 0


def test_node_zero_means_this_plc(plc: VirtualPLC) -> None:
    reply = plc.handle_frame(frame("0601", dest=(0, 0, 0)))
    assert reply is not None and reply[6:8] == b"\x00\x01"  # answered as node 1


def test_broadcast_executes_without_response(plc: VirtualPLC) -> None:
    params = bytes.fromhex("82000000 0001 4242")
    assert plc.handle_frame(frame("0102", params, dest=(0, 0xFF, 0))) is None
    assert plc.memory.read_words(0x82, 0, 1) == [0x4242]


def test_no_response_requested(plc: VirtualPLC) -> None:
    assert plc.handle_frame(frame("0402", b"", icf=0x81)) is None
    assert plc.commands[0x0402] == 1


def test_other_network_gets_a_relay_error(plc: VirtualPLC) -> None:
    reply = plc.handle_frame(frame("0101", bytes.fromhex("82000000 0001"), dest=(3, 1, 0)))
    assert reply is not None
    assert reply[12:16] == bytes.fromhex("8501 0001")  # bit 15 + 0501, relay point net 0 node 1
    assert reply[6:9] == bytes((0, 1, 0))  # from the relay point itself, not from network 3
    relay = VirtualPLC(network=1, node=10)
    reply = relay.handle_frame(frame("0101", bytes.fromhex("82000000 0001"), dest=(3, 5, 0)))
    assert reply is not None and reply[6:9] == bytes((1, 10, 0)) and reply[14:16] == b"\x01\x0a"
    dropping = VirtualPLC(relay_error=None)
    assert dropping.handle_frame(frame("0601", dest=(3, 1, 0))) is None


def test_own_network_number_is_accepted() -> None:
    plc = VirtualPLC(network=3)
    reply = plc.handle_frame(frame("0601", dest=(3, 1, 0)))
    assert reply is not None and reply[12:14] == b"\x00\x00"


def test_unparseable_frames_get_no_answer(plc: VirtualPLC) -> None:
    assert plc.handle_frame(b"\x80\x00") is None
    assert plc.handle_frame(bytes.fromhex("C0 00 02 00 01 00 00 22 00 01 0101 0000")) is None


def test_undefined_command_and_counters(plc: VirtualPLC) -> None:
    assert call(plc, "0A01") == (0x0401, b"")
    call(plc, "0601")
    call(plc, "0601")
    assert plc.frames_handled == 3 and plc.commands[0x0601] == 2


def test_malformed_parameters_answer_the_codec_end_code(plc: VirtualPLC) -> None:
    assert call(plc, "0101", "820000")[0] == 0x1002
    assert call(plc, "0101", "82000000 0001 00")[0] == 0x1001


def test_cpu_error_flags_ride_on_the_end_code(plc: VirtualPLC) -> None:
    plc.raise_error(0x00F7)  # battery error: non-fatal
    assert call(plc, "0601")[0] == 0x0040
    assert call(plc, "2101", "FFFF")[0] == 0x0000  # cleared before the answer is built
    assert call(plc, "0601")[0] == 0x0000


# ---- parameter area ------------------------------------------------------------------------


def test_parameter_area_read_limits(plc: VirtualPLC) -> None:
    plc.parameter_memory[0:4] = b"\x12\x34\x56\x78"
    assert call(plc, "0201", "8010 0000 0002") == (0, bytes.fromhex("8010 0000 0002 1234 5678"))
    code, data = call(plc, "0201", "8002 0000 01F4")  # 500 words
    assert code == 0x1108 and data[4:6] == b"\x01\xf2" and len(data) == 6 + 2 * 498
    code, data = call(plc, "0201", "8010 01FE 0004")  # past the end of 512 words
    assert code == 0x1104 and data[:6] == bytes.fromhex("8010 01FE 8002")
    assert call(plc, "0201", "8010 0200 0001") == (0x1103, b"")
    assert call(plc, "0201", "8010 01FF 0001")[1][4:6] == b"\x80\x01"  # last word flag


def test_parameter_area_write_and_clear(plc: VirtualPLC) -> None:
    assert call(plc, "0202", "8013 0000 0002 AAAA BBBB") == (0, b"")
    assert plc.parameter_memory[2 * 1792 : 2 * 1792 + 4] == b"\xaa\xaa\xbb\xbb"
    assert call(plc, "0202", "8013 01FF 0001 CCCC") == (0, b"")  # last word without bit 15
    assert plc.parameter_memory[2 * 2303 : 2 * 2304] == b"\x00\x00"
    assert call(plc, "0202", "8013 01FF 8001 CCCC") == (0, b"")
    assert plc.parameter_memory[2 * 2303 : 2 * 2304] == b"\xcc\xcc"
    assert call(plc, "0203", "8013 0000 0200 0000") == (0, b"")
    assert not any(plc.parameter_memory[2 * 1792 : 2 * 2304])
    plc.mode = Mode.RUN
    assert call(plc, "0202", "8012 0000 0001 0001")[0] == 0x2206  # I/O table: PROGRAM only


# ---- program area and mode -----------------------------------------------------------------


def test_program_area_write_read_with_last_flag(plc: VirtualPLC) -> None:
    code, data = call(plc, "0307", "FFFF 00000000 0008 0102030405060708")
    assert (code, data) == (0, bytes.fromhex("FFFF 00000000 0008"))
    code, data = call(plc, "0307", "FFFF 00000008 8004 090A0B0C")
    assert (code, data) == (0, bytes.fromhex("FFFF 00000008 8004"))
    assert plc.program_length == 12
    assert call(plc, "0306", "FFFF 00000000 0008") == (
        0,
        bytes.fromhex("FFFF 00000000 0008 0102030405060708"),
    )
    assert call(plc, "0306", "FFFF 00000008 0004") == (
        0,
        bytes.fromhex("FFFF 00000008 8004 090A0B0C"),
    )
    assert call(plc, "0306", "FFFF 00000002 0004")[0] == 0x1102  # not a multiple of 4
    # A shorter program written over it: nothing of the old one's tail comes back.
    assert call(plc, "0307", "FFFF 00000000 8004 0D0E0F10")[0] == 0
    assert call(plc, "0306", "FFFF 00000000 000C") == (
        0,
        bytes.fromhex("FFFF 00000000 800C 0D0E0F10 00000000 00000000"),
    )
    assert call(plc, "0308", "FFFF 00") == (0, b"")
    assert call(plc, "0306", "FFFF 00000000 0004") == (
        0,
        bytes.fromhex("FFFF 00000000 8004 00000000"),
    )


def test_run_without_mode_goes_to_monitor(plc: VirtualPLC) -> None:
    modes = []
    assert call(plc, "0401") == (0, b"")
    modes.append(plc.mode)
    assert call(plc, "0401", "FFFF 04") == (0, b"")
    modes.append(plc.mode)
    assert call(plc, "0401", "FFFF 04") == (0, b"")  # already there: normal
    modes.append(plc.mode)
    assert call(plc, "0402", "FFFF") == (0, b"")
    modes.append(plc.mode)
    assert call(plc, "0401", "FFFF") == (0, b"")
    modes.append(plc.mode)
    assert modes == [Mode.MONITOR, Mode.RUN, Mode.RUN, Mode.PROGRAM, Mode.MONITOR]


# ---- status, configuration, clock ----------------------------------------------------------


def test_cpu_unit_data_read_parts(plc: VirtualPLC) -> None:
    code, a = call(plc, "0501", "00")
    assert code == 0 and len(a) == 92 and a[:20] == b"CJ2M-CPU33".ljust(20)
    assert call(plc, "0501", "01")[1] == bytes(64) + b"\x00\x01"
    assert call(plc, "0501")[1] == a + bytes(64) + b"\x00\x01"


def test_connection_data_read(plc: VirtualPLC) -> None:
    assert call(plc, "0502", "00 19") == (0, b"\x81\x00" + b"CJ2M-CPU33".ljust(20))
    assert call(plc, "0502", "10") == (0, b"\x80")


def test_cpu_unit_status_read(plc: VirtualPLC) -> None:
    plc.mode = Mode.RUN
    plc.messages[2] = "hi"
    code, data = call(plc, "0601")
    assert code == 0
    assert data == bytes.fromhex("05 04 0000 0000 0004 0000") + b" " * 16


def test_cycle_time_read(plc: VirtualPLC) -> None:
    plc.mode = Mode.MONITOR
    plc.cycle_times = [10, 20, 30, 40, 50, 60, 70, 80]
    plc.cycle_max, plc.cycle_min = 90, 5
    assert call(plc, "0620", "01") == (0, bytes.fromhex("0000002D 0000005A 00000005"))
    assert call(plc, "0620", "00") == (0, b"")
    assert call(plc, "0620", "01")[1][4:] == bytes.fromhex("00000050 00000050")


def test_clock_read_and_write_with_omissions(plc: VirtualPLC) -> None:
    assert call(plc, "0701") == (0, bytes.fromhex("24 03 05 10 20 30 02"))
    assert call(plc, "0702", "25 12 31 23 59 58 06") == (0, b"")
    assert call(plc, "0701") == (0, bytes.fromhex("25 12 31 23 59 58 06"))
    assert call(plc, "0702", "26 01 02 03 04") == (0, b"")  # second → 00, weekday kept
    assert call(plc, "0701") == (0, bytes.fromhex("26 01 02 03 04 00 06"))
    assert call(plc, "0702", "26 13 02 03 04")[0] == 0x110C  # month 13: clock not set
    assert call(plc, "0701")[1][:2] == b"\x26\x01"
    assert call(plc, "0702", "26 01")[0] == 0x1002


def test_messages_three_variants(plc: VirtualPLC) -> None:
    plc.messages[0] = "PUMP 1 FAILED"
    plc.fal_messages[5] = "LOW PRESSURE"
    code, data = call(plc, "0920", "0003")
    assert code == 0 and data[:2] == b"\x00\x03"
    assert data[2:34] == b"PUMP 1 FAILED".ljust(32) and data[34:] == b" " * 32
    assert call(plc, "0920", "0000") == (0, b"\x00\x00")
    assert call(plc, "0920", "4001") == (0, b"")
    assert plc.messages == {}
    assert call(plc, "0920", "8005") == (0, b"\x80\x05" + b"LOW PRESSURE".ljust(16))


# ---- access right --------------------------------------------------------------------------


def test_access_right_acquire_names_the_holder(plc: VirtualPLC) -> None:
    assert call(plc, "0C01", "FFFF", node=0x05) == (0, b"")
    assert plc.access_holder == FinsAddress(0, 5, 0)
    assert call(plc, "0C01", "FFFF", node=0x22) == (0x3001, b"\x00\x05\x00")
    assert call(plc, "0402", "FFFF", node=0x22) == (0x3001, b"")
    assert call(plc, "0101", "82000000 0001", node=0x22)[0] == 0  # reads still go
    assert call(plc, "0C02", "FFFF", node=0x22) == (0, b"")
    assert plc.access_holder == FinsAddress(0, 0x22, 0)
    assert call(plc, "0C03", "FFFF", node=0x05) == (0, b"")  # anyone may release
    assert plc.access_holder is None
    assert call(plc, "0C01", "FFFE")[0] == 0x1106


# ---- logs ----------------------------------------------------------------------------------


def test_error_log_read_and_clear(plc: VirtualPLC) -> None:
    for code in (0x4101, 0x00F7, 0x80F1):
        plc.log_error(code)
    code, data = call(plc, "2102", "0001 0002")
    assert code == 0
    assert data[:6] == bytes.fromhex("0014 0003 0002")
    assert data[6:16] == bytes.fromhex("00F7 0000 20 30 05 10 24 03")
    code, data = call(plc, "2102", "0002 0005")  # fewer than asked: what exists + 1104
    assert code == 0x1104 and data[:6] == bytes.fromhex("0014 0003 0001")
    assert call(plc, "2102", "0004 0001") == (0x1103, b"")
    assert call(plc, "2103") == (0, b"")
    assert plc.error_log == []


def test_error_log_keeps_twenty(plc: VirtualPLC) -> None:
    for n in range(25):
        plc.log_error(0x4101 + n)
    assert [r.code1 for r in plc.error_log] == [0x4101 + n for n in range(5, 25)]


def test_write_access_log_rules(plc: VirtualPLC) -> None:
    call(plc, "0102", "82000000 0001 0001", node=0x05)
    call(plc, "0101", "82000000 0001", node=0x06)  # a read is not logged
    call(plc, "0103", "82000000 0001 0002", node=0x07)
    call(plc, "0102", "82000000 0001 0003", node=0x05)  # node 5 again: its record moves last
    code, data = call(plc, "2140", "0000 0014")
    assert code == 0 and data[:6] == bytes.fromhex("0014 0002 0002")
    assert data[6:18] == bytes.fromhex("00 07 00 0103 24 03 05 10 20 30 02")
    assert data[18:30] == bytes.fromhex("00 05 00 0102 24 03 05 10 20 30 02")
    for node in range(10, 40):
        call(plc, "0102", "82000000 0001 0003", node=node)
    assert len(plc.write_log) == 20
    assert plc.write_log[0].source.node == 20 and plc.write_log[-1].source.node == 39
    assert call(plc, "2140", "0015 0001") == (0x1103, b"")
    code, data = call(plc, "2140", "0013 0005")  # fewer than asked: normal end
    assert code == 0 and data[4:6] == b"\x00\x01"
    assert call(plc, "2141") == (0, b"")
    assert plc.write_log == []


def test_error_clear_modes(plc: VirtualPLC) -> None:
    plc.raise_error(0x80F1)  # memory error: fatal
    plc.mode = Mode.MONITOR
    assert call(plc, "2101", "80F1")[0] == 0x2205 | 0x0080  # PROGRAM mode only; fatal flag
    assert call(plc, "2101", "FFFE")[0] == 0x2205 | 0x0080
    plc.mode = Mode.PROGRAM
    assert call(plc, "2101", "FFFE")[0] == 0x0000  # cleared before the answer is built
    assert plc.current_errors == [] and plc.fatal_errors == 0
    plc.raise_error(0x4105, message="LOW PRESSURE")
    assert call(plc, "0601") == (
        0x0040,
        bytes.fromhex("04 00 0000 8000 0000 4105") + b"LOW PRESSURE    ",
    )
    assert call(plc, "2101", "00F7") == (0x0040, b"")  # absent: still normal
    assert call(plc, "2101", "4105") == (0, b"")


def test_the_most_serious_error_is_reported_and_cleared_first(plc: VirtualPLC) -> None:
    """0601 reports "the most serious" error and FFFE clears "the highest priority" one
    (5-3-17, 5-3-27): the fatal one, whatever order they were raised in."""
    plc.raise_error(0x00F7)  # battery error: non-fatal, raised first
    plc.raise_error(0x80F1)  # memory error: fatal
    assert call(plc, "0601")[1][8:10] == b"\x80\xf1"  # the error code
    plc.mode = Mode.RUN
    assert call(plc, "2101", "FFFE")[0] == 0x2206 | 0x00C0  # the fatal one: PROGRAM mode only
    assert plc.current_errors == [0x00F7, 0x80F1]
    plc.mode = Mode.PROGRAM
    assert call(plc, "2101", "FFFE")[0] == 0x0040  # the battery error is still there
    assert plc.current_errors == [0x00F7]
    assert call(plc, "0601")[1][8:10] == b"\x00\xf7"


# ---- file memory ---------------------------------------------------------------------------

NAME = b"DATA    .BIN"


def _dir(path: bytes = b"") -> bytes:
    return len(path).to_bytes(2, "big") + path


def test_single_file_write_modes_and_read(plc: VirtualPLC) -> None:
    def write(mode: int, pos: int, data: bytes, disk: int = 0x8000) -> int:
        params = disk.to_bytes(2, "big") + mode.to_bytes(2, "big") + NAME
        params += pos.to_bytes(4, "big") + len(data).to_bytes(2, "big") + data + _dir()
        return call(plc, "2203", params)[0]

    assert write(0, 0, b"hello") == 0
    assert write(0, 0, b"again") == 0x2107  # exists
    assert write(2, 0, b" world") == 0
    assert write(3, 0, b"J") == 0
    assert write(3, 99, b"J") == 0x1103
    assert write(2, 0, b"x", disk=0x8001) == 0x2106  # no such file on the EM file memory
    assert write(0, 0, b"x", disk=0x8002) == 0x110C  # the codec knows only 8000/8001
    del plc.file_memory[0x8001]
    assert write(0, 0, b"x", disk=0x8001) == 0x2301  # no EM file memory
    read = b"\x80\x00" + NAME + bytes.fromhex("00000000 0020") + _dir()
    assert call(plc, "2202", read) == (0, bytes.fromhex("0000000B 00000000 800B") + b"Jello world")
    read = b"\x80\x00" + NAME + bytes.fromhex("00000001 0002") + _dir()
    assert call(plc, "2202", read) == (0, bytes.fromhex("0000000B 00000001 0002") + b"el")
    assert write(1, 0, b"new") == 0  # overwrite
    probe = b"\x80\x00" + NAME + bytes.fromhex("00000000 0000") + _dir()
    assert call(plc, "2202", probe) == (0, bytes.fromhex("00000003 00000000 0000"))
    missing = b"\x80\x00" + b"NOPE    .BIN" + bytes.fromhex("00000000 0000") + _dir()
    assert call(plc, "2202", missing)[0] == 0x2006


def test_file_name_read_directories_copy_rename_delete(plc: VirtualPLC) -> None:
    fm = plc.file_memory[0x8000]
    fm.write((), "A.TXT", 0, 0, b"12345")
    assert call(plc, "2215", b"\x80\x00\x00\x00" + b"SUB         " + _dir()) == (0, b"")
    assert call(plc, "2215", b"\x80\x00\x00\x00" + b"SUB         " + _dir())[0] == 0x2107
    code, data = call(plc, "2201", bytes.fromhex("8000 0000 0014") + _dir())
    assert code == 0
    assert data[:12] == b" " * 12 and data[16:20] == (64 * 1024 * 1024).to_bytes(4, "big")
    assert data[24:28] == bytes.fromhex("0002 8002")
    assert data[28:40] == b"A       .TXT" and data[44:48] == b"\x00\x00\x00\x05"
    assert data[48:50] == b"\x00\x20" and data[50:62] == b"SUB         " and data[71] == 0x10
    # the file date is the PLC clock, MS-DOS layout
    assert (
        int.from_bytes(data[40:44], "big")
        == (44 << 25) | (3 << 21) | (5 << 16) | (10 << 11) | (20 << 5) | 15
    )
    code, data = call(plc, "2201", bytes.fromhex("8000 0000 0000") + _dir(b"\\SUB"))
    assert data[24:28] == bytes.fromhex("0002 0000")  # "." and ".."
    copy = b"\x80\x00A       .TXT\x80\x00B       .TXT" + _dir() + _dir(b"\\SUB")
    assert call(plc, "2207", copy) == (0, b"")
    assert call(plc, "2207", copy)[0] == 0x2107
    assert fm.file(("SUB",), "B.TXT").data == b"12345"
    rename = b"\x80\x00B       .TXTC       .TXT" + _dir(b"\\SUB")
    assert call(plc, "2208", rename) == (0, b"")
    assert call(plc, "2215", b"\x80\x00\x00\x01" + b"SUB         " + _dir())[0] == 0x2108
    delete = b"\x80\x00\x00\x02C       .TXTZ       .TXT" + _dir(b"\\SUB")
    assert call(plc, "2205", delete) == (0, b"\x00\x01")
    assert call(plc, "2215", b"\x80\x00\x00\x01" + b"SUB         " + _dir()) == (0, b"")
    assert call(plc, "2204", "8000") == (0, b"")
    assert fm.listing(()) == []


def test_memory_area_file_transfer_and_compare(plc: VirtualPLC) -> None:
    plc.memory.write_words(0x82, 0, [1, 2, 3])
    tail = b"\x80\x00" + NAME + _dir()
    assert call(plc, "220A", bytes.fromhex("0000 82 0000 00 0003") + tail) == (0, b"\x00\x03")
    assert plc.file_memory[0x8000].file((), "DATA.BIN").data == bytes.fromhex("000100020003")
    assert call(plc, "220A", bytes.fromhex("0000 82 0000 00 0003") + tail)[0] == 0x2107
    assert call(plc, "220A", bytes.fromhex("0001 B1 0000 00 0003") + tail) == (0, b"\x00\x03")
    assert plc.memory.read_words(0xB1, 0, 3) == [1, 2, 3]
    assert call(plc, "220A", bytes.fromhex("0002 82 0000 00 0003") + tail) == (0, b"\x00\x03")
    plc.memory.write_words(0x82, 1, [9])
    assert call(plc, "220A", bytes.fromhex("0002 82 0000 00 0003") + tail) == (0x2007, b"\x00\x01")


def test_parameter_and_program_area_file_transfer(plc: VirtualPLC) -> None:
    plc.parameter_memory[0:2] = b"\x55\xaa"
    tail = b"\x80\x01" + NAME + _dir()
    assert call(plc, "220B", bytes.fromhex("0000 8010 0000 FFFF") + tail) == (0, b"\x02\x00")
    assert call(plc, "220B", bytes.fromhex("0002 8010 0000 FFFF") + tail) == (0, b"\x02\x00")
    call(plc, "0307", "FFFF 00000000 8004 DEADBEEF")
    tail = b"\x80\x00" + NAME + _dir()
    head = "FFFF 00000000 FFFFFFFF"
    assert call(plc, "220C", bytes.fromhex("0000" + head) + tail) == (0, b"\x00\x00\x00\x04")
    call(plc, "0308", "FFFF 00")
    assert call(plc, "220C", bytes.fromhex("0001" + head) + tail) == (0, b"\x00\x00\x00\x04")
    assert plc.program[:4] == bytes.fromhex("DEADBEEF") and plc.program_length == 4
    assert call(plc, "220C", bytes.fromhex("0002" + head) + tail) == (0, b"\x00\x00\x00\x04")


def test_area_file_transfers_check_their_fixed_parameters(plc: VirtualPLC) -> None:
    """Manual 5-3-40/5-3-41: 220B's begin is always 0000 and its count FFFF; 220C's begin
    00000000 and its byte count FFFFFFFF. Anything else is refused (1103 begin, 1104 count)."""
    tail = b"\x80\x01" + NAME + _dir()
    assert call(plc, "220B", bytes.fromhex("0000 8010 0001 FFFF") + tail) == (0x1103, b"")
    assert call(plc, "220B", bytes.fromhex("0000 8010 0000 0200") + tail) == (0x1104, b"")
    tail = b"\x80\x00" + NAME + _dir()
    assert call(plc, "220C", bytes.fromhex("0000 FFFF 00000004 FFFFFFFF") + tail) == (0x1103, b"")
    assert call(plc, "220C", bytes.fromhex("0000 FFFF 00000000 00000400") + tail) == (0x1104, b"")


# ---- serial gateway ------------------------------------------------------------------------


def test_serial_gateway_default_and_custom(plc: VirtualPLC) -> None:
    assert call(plc, "2804", "01 03 0000 0002") == (0, bytes.fromhex("01 03 04 00000000"))
    assert call(plc, "2804", "01 06 0010 1234") == (0, bytes.fromhex("01 06 0010 1234"))
    assert call(plc, "2804", "01 10 0010 0001 02 1234") == (0, bytes.fromhex("01 10 0010 0001"))
    assert call(plc, "2804", "01 01 0000 0009") == (0, bytes.fromhex("01 01 02 0000"))
    assert call(plc, "2804", "01 2B 0E01 00") == (0, bytes.fromhex("01 AB 01"))
    assert call(plc, "2805", b"0103000A0001") == (0, b"0103020000")
    assert call(plc, "2803", b"01000" + b"0101" + b"C00000") == (
        0,
        b"0100" + b"00" + b"0101" + b"0000",
    )
    plc.gateway = lambda code, params: b"\x01\x03\x02\x00\x2a"
    assert call(plc, "2804", "01 03 0000 0001") == (0, bytes.fromhex("01 03 02 002A"))


# ---- the codec agrees with every normal response -------------------------------------------

ROUND_TRIP = [
    ("0101", "82000000 0003"),
    ("0104", "82000000 30000102 DC010000"),
    ("0201", "8010 0000 0010"),
    ("0306", "FFFF 00000000 0010"),
    ("0307", "FFFF 00000000 8004 01020304"),
    ("0501", ""),
    ("0501", "00"),
    ("0502", "00 19"),
    ("0601", ""),
    ("0701", ""),
    ("0920", "0005"),
    ("0920", "8001"),
    ("2102", "0000 0001"),
    ("2140", "0000 0001"),
    ("2201", "8000 0000 0014 0000"),
    ("2202", "8000" + NAME.hex() + "00000000 0003 0000"),
    ("2205", "8000 0001" + NAME.hex() + "0000"),
    ("220A", "0002 82 0000 00 0002 8000" + NAME.hex() + "0000"),
    ("220C", "0002 FFFF 00000000 FFFFFFFF 8000" + NAME.hex() + "0000"),
    ("2803", b"01000".hex() + b"0101".hex()),
    ("2804", "01 03 0000 0001"),
]


@pytest.mark.parametrize(("command", "params"), ROUND_TRIP)
def test_codec_parses_and_reencodes_every_response(command: str, params: str) -> None:
    plc = VirtualPLC(mode=Mode.PROGRAM, clock=lambda: T0)
    plc.log_error(0x4101)
    plc.messages[0] = "M0"
    plc.program_length = 4
    plc.file_memory[0x8000].write((), "DATA.BIN", 0, 0, b"\x00\x00\x00\x00")
    call(plc, "0102", "82000000 0001 0000")  # one write access record
    raw = bytes.fromhex(params)
    code, data = call(plc, command, raw)
    assert code == 0
    mrc, src = bytes.fromhex(command)
    result = decode_request(mrc, src, raw).decode_response(data)
    assert encode_result(result) == data


# ---- robustness ----------------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(code=st.sampled_from(sorted(HANDLERS)), params=st.binary(max_size=80))
def test_any_parameters_get_an_answer(code: int, params: bytes) -> None:
    plc = VirtualPLC(mode=Mode.MONITOR, clock=lambda: T0)
    plc.file_memory[0x8000].write((), "DATA.BIN", 0, 0, b"0123456789")
    reply = plc.handle_frame(frame(f"{code:04X}", params))
    assert reply is not None and reply[10:12] == code.to_bytes(2, "big")
