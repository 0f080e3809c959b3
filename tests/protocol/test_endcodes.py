"""End codes (manual 5-1-3): the table, the flag bits and the error mapping."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol import errors
from aiofins.protocol.endcodes import (
    END_CODES,
    MAIN_CODE_NAMES,
    NORMAL,
    SECTION_END_CODES,
    EndCode,
)
from aiofins.protocol.header import FinsAddress, Header, ResponseFrame

# Every (main, sub) pair of manual 5-1-3, main codes 22/23/24 as reconstructed.
MANUAL_SUB_CODES: dict[int, list[int]] = {
    0x00: [0x00, 0x01],
    0x01: [0x01, 0x02, 0x03, 0x04, 0x05, 0x06],
    0x02: [0x01, 0x02, 0x03, 0x04, 0x05],
    0x03: [0x01, 0x02, 0x03, 0x04],
    0x04: [0x01, 0x02],
    0x05: [0x01, 0x02, 0x03, 0x04],
    0x10: [0x01, 0x02, 0x03, 0x04, 0x05],
    0x11: [0x01, 0x02, 0x03, 0x04, 0x06, 0x09, 0x0A, 0x0B, 0x0C],
    0x20: [0x02, 0x03, 0x04, 0x05, 0x06, 0x07],
    0x21: [0x01, 0x02, 0x03, 0x05, 0x06, 0x07, 0x08],
    0x22: [0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08],
    0x23: [0x01, 0x02, 0x03],
    0x24: [0x01],
    0x25: [0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x09, 0x0A, 0x0D, 0x0F, 0x10],
    0x26: [0x01, 0x02, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x0A, 0x0B],
    0x30: [0x01],
    0x40: [0x01],
}
ALL_MANUAL_CODES = sorted((m << 8) | s for m, subs in MANUAL_SUB_CODES.items() for s in subs)


def test_table_has_exactly_the_manual_codes() -> None:
    assert sorted(END_CODES) == ALL_MANUAL_CODES
    assert len(END_CODES) == 85
    assert sorted(MAIN_CODE_NAMES) == sorted(MANUAL_SUB_CODES)


@pytest.mark.parametrize("code", ALL_MANUAL_CODES, ids=lambda c: f"{c:04X}")
def test_every_entry_has_name_cause_and_correction(code: int) -> None:
    info = END_CODES[code]
    assert info.code == code
    assert info.main_name == MAIN_CODE_NAMES[code >> 8]
    assert info.sub_name
    assert info.causes
    for cause in info.causes:
        assert cause.cause.strip(), f"{code:04X} has a row without a cause"
        assert cause.correction.strip(), f"{code:04X} has a row without a correction"
        assert "---" not in (cause.cause, cause.correction, cause.check_point)
        assert "  " not in cause.cause + cause.correction
        assert " | " not in cause.cause + cause.correction + cause.check_point
    end_code = EndCode(code)
    assert end_code.name.endswith(info.sub_name)
    assert end_code.cause and end_code.correction


@pytest.mark.parametrize(
    ("code", "name"),
    [
        (0x0000, "Normal completion"),
        (0x0001, "Normal completion: Service canceled"),
        (0x0205, "Destination node error: Response timeout"),
        (0x1001, "Command format error: Command too long"),
        (0x1002, "Command format error: Command too short"),
        (0x1103, "Parameter error: Address range error"),
        (0x1104, "Parameter error: Address range exceeded"),
        (0x2101, "Write not possible: Read-only"),
        (0x2102, "Write not possible: Protected"),
        (0x2201, "Not executable in current mode: Not possible during execution"),
        (0x2207, "Not executable in current mode: Specified node not polling node"),
        (0x2208, "Not executable in current mode: Step cannot be executed"),
        (0x2301, "No such device: File device missing"),
        (0x2302, "No such device: Memory missing"),
        (0x2303, "No such device: Clock missing"),
        (0x2401, "Cannot start/stop: Table missing"),
        (0x2604, "Command error: Protected"),
        (0x2605, "Command error: Service already executing"),
        (0x3001, "Access right error: No access right"),
        (0x4001, "Abort: Service aborted"),
    ],
)
def test_names(code: int, name: str) -> None:
    assert EndCode(code).name == name


def test_reconstructed_mode_codes_keep_their_modes() -> None:
    causes = {code: END_CODES[code].causes[0].cause for code in range(0x2203, 0x2207)}
    assert causes == {
        0x2203: "The PLC is in PROGRAM mode.",
        0x2204: "The PLC is in DEBUG mode.",
        0x2205: "The PLC is in MONITOR mode.",
        0x2206: "The PLC is in RUN mode.",
    }
    assert END_CODES[0x2303].causes[0].cause == "There is no clock."
    assert len(END_CODES[0x2303].causes) == 1  # the manual's empty row is dropped


def test_multi_cause_rows() -> None:
    busy = END_CODES[0x2604]
    assert [c.check_point for c in busy.causes] == ["", "Number of commands being executed"]
    assert "already processing 5 commands" in busy.causes[1].cause
    assert len(END_CODES[0x0205].causes) == 3
    assert END_CODES[0x2003].causes[1].check_point == "Table"
    assert " / " in EndCode(0x2604).cause


def test_unknown_sub_code_uses_main_name() -> None:
    assert EndCode(0x1199).name == "Parameter error: unknown sub code 19"
    assert EndCode(0x2539).name == "Unit error: unknown sub code 39"
    assert EndCode(0x7F3F).name == "unknown end code"
    assert EndCode(0x1199).cause == ""
    assert EndCode(0x1199).correction == ""


@pytest.mark.parametrize(
    ("mres", "sres", "code", "relay", "fatal", "non_fatal", "normal"),
    [
        (0x00, 0x00, 0x0000, False, False, False, True),
        (0x00, 0x40, 0x0000, False, False, True, True),  # battery error, command fine
        (0x00, 0x80, 0x0000, False, True, False, True),
        (0x00, 0xC0, 0x0000, False, True, True, True),
        (0x11, 0x44, 0x1104, False, False, True, False),
        (0x82, 0x05, 0x0205, True, False, False, False),
        (0x80, 0x00, 0x0000, True, False, False, False),  # relay flag on code 0: not normal
        (0xA6, 0xC4, 0x2604, True, True, True, False),
        (0xFF, 0xFF, 0x7F3F, True, True, True, False),
    ],
)
def test_flag_bits(
    mres: int,
    sres: int,
    code: int,
    relay: bool,
    fatal: bool,
    non_fatal: bool,
    normal: bool,
) -> None:
    end_code = EndCode.from_bytes(mres, sres)
    assert end_code.raw == (mres << 8) | sres
    assert end_code.code == code
    assert end_code.main == code >> 8
    assert end_code.sub == code & 0xFF
    assert end_code.relay_error is relay
    assert end_code.fatal_cpu_error is fatal
    assert end_code.non_fatal_cpu_error is non_fatal
    assert end_code.is_normal is normal


def test_str_shows_code_name_and_flags() -> None:
    assert str(NORMAL) == "0000 Normal completion"
    assert str(EndCode(0x0040)) == "0000 Normal completion [non-fatal CPU error]"
    assert str(EndCode(0x0080)) == "0000 Normal completion [fatal CPU error]"
    assert str(EndCode(0x8205)) == ("0205 Destination node error: Response timeout [relay error]")


@given(st.integers(0, 0xFFFF))
def test_any_word_decodes(raw: int) -> None:
    end_code = EndCode(raw)
    assert end_code.code == raw & 0x7F3F
    assert (end_code.main << 8) | end_code.sub == end_code.code
    assert isinstance(end_code.name, str) and end_code.name
    assert str(end_code).startswith(f"{end_code.code:04X} ")


def _response(mres: int, sres: int, tail: bytes = b"") -> bytes:
    header = Header(FinsAddress(0, 0x22, 0), FinsAddress(0, 0x0A, 0), sid=7, icf=0xC0)
    return header.encode() + bytes((0x01, 0x01, mres, sres)) + tail


def test_0040_response_is_normal_with_data() -> None:
    frame = ResponseFrame.decode(_response(0x00, 0x40, b"\x12\x34"))
    assert frame.end_code.is_normal
    assert frame.end_code.non_fatal_cpu_error
    assert frame.data == b"\x12\x34"
    assert frame.relay is None


def test_relay_error_response_carries_network_and_node() -> None:
    # Wire-format 8.4: 82 05 01 05 = response timeout reported by network 1, node 5.
    frame = ResponseFrame.decode(_response(0x82, 0x05, b"\x01\x05"))
    assert frame.end_code.relay_error
    assert frame.end_code.code == 0x0205
    assert frame.relay == (1, 5)
    assert frame.data == b""


@pytest.mark.parametrize(
    ("code", "cls"),
    [
        (0x0001, errors.ServiceCanceledError),
        (0x0101, errors.LocalNodeError),
        (0x0205, errors.DestinationNodeError),
        (0x0302, errors.ControllerError),
        (0x0401, errors.ServiceUnsupportedError),
        (0x0504, errors.RoutingTableError),
        (0x1002, errors.CommandFormatError),
        (0x1104, errors.ParameterError),
        (0x2006, errors.ReadNotPossibleError),
        (0x2101, errors.WriteNotPossibleError),
        (0x2203, errors.ModeError),
        (0x2303, errors.NoSuchDeviceError),
        (0x2401, errors.CannotStartStopError),
        (0x250F, errors.UnitError),
        (0x2604, errors.CommandRejectedError),
        (0x3001, errors.AccessRightError),
        (0x4001, errors.AbortedError),
    ],
)
def test_error_for_end_code(code: int, cls: type[errors.EndCodeError]) -> None:
    exc = errors.error_for_end_code(EndCode(code | 0x0040), command_code=0x0102)
    assert type(exc) is cls
    assert isinstance(exc, errors.FinsError)
    assert exc.code == code
    text = str(exc)
    assert text.startswith(f"command 0102 failed, end code {code:04X}: ")
    assert END_CODES[code].sub_name in text
    assert END_CODES[code].causes[0].correction in text


def test_busy_codes_and_access_right_holder() -> None:
    busy = errors.error_for_end_code(EndCode(0x2604))
    assert isinstance(busy, errors.CommandRejectedError) and busy.is_busy
    protected = errors.error_for_end_code(EndCode(0x2602))
    assert isinstance(protected, errors.CommandRejectedError) and not protected.is_busy
    # Wire-format 8.4: 30 01 followed by 00 05 00 = held by network 0, node 5, unit 0.
    held = errors.error_for_end_code(EndCode(0x3001), command_code=0x0C01, data=b"\x00\x05\x00")
    assert isinstance(held, errors.AccessRightError)
    assert held.holder == (0, 5, 0)


def test_relay_error_message_names_the_relay_point() -> None:
    exc = errors.RelayError(EndCode(0x8205), network=1, node=5)
    assert str(exc).startswith("relay error at network 1 node 5: end code 0205")
    assert exc.network == 1 and exc.node == 5


def test_1108_from_parameter_area_read_has_a_name() -> None:
    """5-3-7 answers 1108 (over 498 words); 5-1-3's table has no such row."""
    assert 0x1108 not in END_CODES and set(SECTION_END_CODES) == {0x1108}
    code = EndCode(0x1108)
    assert code.name == "Parameter error: Too many words"
    assert "498" in code.cause and "498" in code.correction
    exc = errors.error_for_end_code(code, command_code=0x0201)
    assert isinstance(exc, errors.ParameterError) and "Too many words" in str(exc)
