"""The FINS header and whole command/response frames, with real bytes."""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.endcodes import EndCode
from aiofins.protocol.errors import CommandError, DecodeError, FrameError
from aiofins.protocol.header import (
    DEFAULT_GCT,
    HEADER_SIZE,
    ICF_GATEWAY,
    ICF_NO_RESPONSE,
    ICF_RESPONSE,
    MAX_FRAME_SIZE,
    CommandFrame,
    FinsAddress,
    Header,
    ResponseFrame,
    build_command,
)

# Wire-format 8.1: read D100 x 10, client node 0x22, PLC node 0x0A, SID 01.
READ_D100 = bytes.fromhex("80 00 02 00 0A 00 00 22 00 01 01 01 82 00 64 00 00 0A")
READ_D100_REPLY = bytes.fromhex(
    "C0 00 02 00 22 00 00 0A 00 01 01 01 00 00"
    "00 01 00 02 00 03 00 04 00 05 00 06 00 07 00 08 00 09 00 0A"
)
PLC = FinsAddress(0, 0x0A, 0)
CLIENT = FinsAddress(0, 0x22, 0)


def test_encode_worked_example() -> None:
    frame = build_command(PLC, CLIENT, 0x01, 0x01, 0x01, bytes.fromhex("820064 00 000A"))
    assert frame == READ_D100
    assert len(frame) == 18


def test_decode_worked_example() -> None:
    command = CommandFrame.decode(READ_D100)
    assert command.header == Header(PLC, CLIENT, sid=1, icf=0x80, rsv=0, gct=2)
    assert (command.mrc, command.src, command.command_code) == (0x01, 0x01, 0x0101)
    assert command.params == bytes.fromhex("82006400000A")
    assert command.header.response_required and not command.header.is_response
    assert command.encode() == READ_D100


def test_reply_to_worked_example() -> None:
    command = CommandFrame.decode(READ_D100)
    data = b"".join(n.to_bytes(2, "big") for n in range(1, 11))
    reply = ResponseFrame.reply_to(command, 0, data)
    assert reply.encode() == READ_D100_REPLY
    decoded = ResponseFrame.decode(READ_D100_REPLY)
    assert decoded == reply
    assert decoded.header.destination == CLIENT and decoded.header.source == PLC
    assert decoded.end_code.is_normal and decoded.command_code == 0x0101
    assert decoded.data == data


def test_header_field_offsets() -> None:
    header = Header(
        FinsAddress(0x01, 0x02, 0x03),
        FinsAddress(0x04, 0x05, 0x06),
        sid=0x07,
        icf=0x81,
        rsv=0x00,
        gct=0x07,
    )
    raw = header.encode()
    assert raw == bytes((0x81, 0x00, 0x07, 1, 2, 3, 4, 5, 6, 7))
    assert len(raw) == HEADER_SIZE
    assert Header.decode(raw) == header


def test_icf_bits() -> None:
    assert (ICF_GATEWAY, ICF_RESPONSE, ICF_NO_RESPONSE) == (0x80, 0x40, 0x01)
    no_reply = build_command(PLC, CLIENT, 5, 0x04, 0x01, b"", response_required=False)
    assert no_reply[0] == 0x81
    assert not Header.decode(no_reply).response_required
    assert build_command(PLC, CLIENT, 5, 0x04, 0x01)[0] == 0x80
    assert Header.decode(bytes((0xC1,)) + bytes(9)).is_response
    # The default GCT is the classic 02 (wire-format 1.3); 07 is accepted on request.
    assert DEFAULT_GCT == 2
    assert build_command(PLC, CLIENT, 5, 0x04, 0x01, gct=7)[2] == 0x07


def test_reply_header_swaps_addresses_and_sets_response_bit() -> None:
    header = Header(FinsAddress(1, 2, 3), FinsAddress(4, 5, 6), sid=0x99, icf=0x81, gct=7)
    reply = header.reply_header()
    assert reply.destination == FinsAddress(4, 5, 6)
    assert reply.source == FinsAddress(1, 2, 3)
    assert reply.sid == 0x99 and reply.gct == 7 and reply.rsv == 0
    assert reply.icf == 0xC0  # response bit on, no-response bit off, gateway bit kept
    assert reply.encode() == bytes((0xC0, 0x00, 0x07, 4, 5, 6, 1, 2, 3, 0x99))
    assert reply.reply_header().destination == header.destination


def test_relay_error_trailer_round_trip() -> None:
    command = CommandFrame.decode(READ_D100)
    reply = ResponseFrame.reply_to(command, 0x8205, relay=(1, 5))
    raw = reply.encode()
    assert raw[10:] == bytes.fromhex("0101 8205 0105")
    decoded = ResponseFrame.decode(raw)
    assert decoded.relay == (1, 5) and decoded.data == b""
    assert decoded.end_code.relay_error and decoded.end_code.code == 0x0205


def test_relay_error_without_trailer_is_a_frame_error() -> None:
    with pytest.raises(FrameError, match="trailer"):
        ResponseFrame.decode(READ_D100_REPLY[:12] + b"\x82\x05\x01")


def test_flagged_normal_completion_keeps_data() -> None:
    raw = READ_D100_REPLY[:12] + b"\x00\x40" + READ_D100_REPLY[14:]
    decoded = ResponseFrame.decode(raw)
    assert decoded.end_code == EndCode(0x0040)
    assert decoded.end_code.is_normal and decoded.end_code.non_fatal_cpu_error
    assert decoded.data == READ_D100_REPLY[14:]
    assert decoded.encode() == raw


@pytest.mark.parametrize(
    ("raw", "match", "end_code"),
    [
        (READ_D100[:9], "shorter than its header", 0x1002),
        (READ_D100[:11], "no command code", 0x1002),
        (bytes((0x80, 0, 2, 0x80)) + READ_D100[4:], "network address above 127", 0x1005),
        (READ_D100[:12] + bytes(2001), "exceeds 2012", 0x1001),
    ],
)
def test_command_decode_errors(raw: bytes, match: str, end_code: int) -> None:
    with pytest.raises(FrameError, match=match) as info:
        CommandFrame.decode(raw)
    assert info.value.end_code == end_code


def test_command_and_response_bits_are_checked() -> None:
    with pytest.raises(FrameError, match="response bit"):
        CommandFrame.decode(READ_D100_REPLY)
    with pytest.raises(FrameError, match="not a response"):
        ResponseFrame.decode(READ_D100)
    with pytest.raises(FrameError, match="no end code"):
        ResponseFrame.decode(READ_D100_REPLY[:13])


def test_largest_frames() -> None:
    command = build_command(PLC, CLIENT, 0, 0x01, 0x02, bytes(2000))
    assert len(command) == MAX_FRAME_SIZE
    assert CommandFrame.decode(command).params == bytes(2000)
    with pytest.raises(CommandError, match="2000"):
        build_command(PLC, CLIENT, 0, 0x01, 0x02, bytes(2001))
    reply = ResponseFrame.reply_to(CommandFrame.decode(command), 0, bytes(1998)).encode()
    assert len(reply) == MAX_FRAME_SIZE
    assert ResponseFrame.decode(reply).data == bytes(1998)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"network": 128}, "network address 128"),
        ({"node": 256}, "node address 256"),
        ({"unit": -1}, "unit address -1"),
    ],
)
def test_address_validation(kwargs: dict[str, int], match: str) -> None:
    with pytest.raises(CommandError, match=match):
        FinsAddress(**kwargs)


def test_address_of_text_or_address() -> None:
    address = FinsAddress(1, 10, 0)
    assert FinsAddress.of(address) is address
    assert FinsAddress.of("1.10") == address
    with pytest.raises(CommandError, match=r"is not NET\.NODE"):
        FinsAddress.of("node10")


def test_address_parse() -> None:
    assert FinsAddress.parse("1.10.0") == FinsAddress(1, 10, 0)
    assert FinsAddress.parse("0.5") == FinsAddress(0, 5, 0)
    assert str(FinsAddress(1, 10, 0)) == "1.10.0"
    for bad in ("5", "a.b", "1.2.3.4", "1..2"):
        with pytest.raises(CommandError):
            FinsAddress.parse(bad)
    with pytest.raises(CommandError):
        Header(PLC, CLIENT, sid=256)


addresses = st.builds(FinsAddress, st.integers(0, 127), st.integers(0, 255), st.integers(0, 255))
headers = st.builds(
    Header,
    addresses,
    addresses,
    sid=st.integers(0, 255),
    icf=st.sampled_from([0x80, 0x81]),
    rsv=st.just(0),
    gct=st.integers(0, 7),
)


@given(headers, st.integers(0, 255), st.integers(0, 255), st.binary(max_size=2000))
def test_command_round_trip(header: Header, mrc: int, src: int, params: bytes) -> None:
    frame = CommandFrame(header, mrc, src, params)
    raw = frame.encode()
    assert raw[:10] == header.encode() and raw[10:12] == bytes((mrc, src))
    assert CommandFrame.decode(raw) == frame


@given(
    headers,
    st.integers(0, 255),
    st.integers(0, 255),
    st.integers(0, 0xFFFF),
    st.binary(max_size=1996),
    st.tuples(st.integers(0, 127), st.integers(0, 255)),
)
def test_response_round_trip(
    header: Header, mrc: int, src: int, raw_code: int, data: bytes, relay: tuple[int, int]
) -> None:
    end_code = EndCode(raw_code)
    response = ResponseFrame(
        header.reply_header(), mrc, src, end_code, data, relay if end_code.relay_error else None
    )
    raw = response.encode()
    assert raw[12:14] == raw_code.to_bytes(2, "big")
    assert ResponseFrame.decode(raw) == response


@given(st.binary(max_size=40) | st.binary(min_size=2000, max_size=2100))
def test_arbitrary_bytes_raise_only_decode_errors(raw: bytes) -> None:
    for decode in (Header.decode, CommandFrame.decode, ResponseFrame.decode):
        with contextlib.suppress(DecodeError):
            decode(raw)


def test_docs_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """Each example in docs/protocol.md runs and prints what the page says after it."""
    doc = (Path(__file__).parents[2] / "docs" / "protocol.md").read_text()
    examples = re.findall(r"```python\n(.*?)```\n\nOutput:\n\n```\n(.*?)```", doc, re.S)
    assert len(examples) == 2
    for code, output in examples:
        exec(compile(code, "docs/protocol.md", "exec"), {})
        assert capsys.readouterr().out == output
