"""Host Link FINS framing (W342 §3-5, wire-format §4 and §8.3): FCS, frames, line decoder."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol import hostlink
from aiofins.protocol.errors import CommandError, DecodeError, FrameError
from aiofins.protocol.header import CommandFrame, FinsAddress, Header, ResponseFrame
from aiofins.protocol.hostlink import LineDecoder, decode_command, decode_response, fcs

READ_PARAMS = bytes.fromhex("82006400000A")  # D100, 10 words
# Wire-format 8.3, character for character.
DIRECT_COMMAND = b"@00FA000000000010182006400000A0E*\r"
DIRECT_RESPONSE = b"@00FA004000000001010000000100020003000400050006000700080009000A33*\r"
NETWORK_COMMAND = b"@00FA080000201050000000000010182006400000A00*\r"
WORDS_1_TO_10 = b"".join(n.to_bytes(2, "big") for n in range(1, 11))


def _direct_read(sid: int = 0) -> CommandFrame:
    return CommandFrame(Header(FinsAddress(), FinsAddress(), sid=sid), 0x01, 0x01, READ_PARAMS)


@pytest.mark.parametrize(
    ("chars", "expected"),
    [
        (b"@00FA000000000010182006400000A", 0x0E),
        (b"@00FA004000000001010000000100020003000400050006000700080009000A", 0x33),
        (b"@00FA080000201050000000000010182006400000A", 0x00),
        (b"@10RR00310001", 0x42),  # W227's C-mode example
        (b"@00FA0000000000101B00066000006", 0x03),  # public FA sample (wire-format 4.1)
        (b"", 0x00),
        (b"@", 0x40),
    ],
)
def test_fcs(chars: bytes, expected: int) -> None:
    assert fcs(chars) == expected


def test_direct_command_bytes() -> None:
    line = hostlink.encode_command(_direct_read())
    assert line == DIRECT_COMMAND
    assert len(line) == 34
    decoded = decode_command(line)
    assert (decoded.unit, decoded.wait_time, decoded.full_header) == (0, 0, False)
    assert decoded.frame.command_code == 0x0101
    assert decoded.frame.params == READ_PARAMS


def test_network_command_bytes() -> None:
    frame = CommandFrame(Header(FinsAddress(1, 5, 0), FinsAddress()), 0x01, 0x01, READ_PARAMS)
    line = hostlink.encode_command(frame)
    assert line == NETWORK_COMMAND
    decoded = decode_command(line)
    assert decoded.full_header
    assert decoded.frame == frame


def test_unit_and_wait_time_characters() -> None:
    line = hostlink.encode_command(_direct_read(sid=0x12), unit=31, wait_time=0xA)
    assert line.startswith(b"@31FAA00000012")
    decoded = decode_command(line)
    assert (decoded.unit, decoded.wait_time, decoded.frame.header.sid) == (31, 10, 0x12)
    full = hostlink.encode_command(_direct_read(), full_header=True)
    assert full.startswith(b"@00FA0800002000000000000")
    assert decode_command(full).full_header


def test_direct_response_bytes() -> None:
    unit, response = decode_response(DIRECT_RESPONSE, full_header=False)
    assert unit == 0
    assert response.header.icf == 0x40
    assert response.command_code == 0x0101
    assert response.end_code.is_normal
    assert response.data == WORDS_1_TO_10
    # The server side produces the same characters from the command it decoded.
    command = decode_command(DIRECT_COMMAND).frame
    reply = ResponseFrame.reply_to(command, 0, WORDS_1_TO_10)
    assert hostlink.encode_response(reply) == DIRECT_RESPONSE


def test_network_response_round_trip() -> None:
    command = decode_command(NETWORK_COMMAND).frame
    reply = ResponseFrame.reply_to(command, 0x0040, WORDS_1_TO_10[:4])
    line = hostlink.encode_response(reply, unit=7, full_header=True)
    assert line.startswith(b"@07FA00C00002000000010500")
    unit, decoded = decode_response(line, full_header=True)
    assert unit == 7
    assert decoded == reply
    assert decoded.end_code.non_fatal_cpu_error


def test_error_response() -> None:
    command = decode_command(DIRECT_COMMAND).frame
    line = hostlink.encode_response(ResponseFrame.reply_to(command, 0x1103))
    assert line[:-4] == b"@00FA00400000000101" + b"1103"
    _, response = decode_response(line, full_header=False)
    assert response.end_code.code == 0x1103 and response.data == b""


@pytest.mark.parametrize(
    ("line", "match"),
    [
        (DIRECT_RESPONSE.replace(b"33*", b"34*"), "FCS mismatch"),
        (DIRECT_RESPONSE[:-2] + b"\r", "terminator"),
        (DIRECT_RESPONSE[:-1], "terminator"),
        (DIRECT_RESPONSE.replace(b"33*", b"G3*"), "FCS"),
        (b"X" + DIRECT_RESPONSE[1:], "'@'"),
        (b"@0*\r", "too short"),
    ],
)
def test_framing_faults(line: bytes, match: str) -> None:
    with pytest.raises(FrameError, match=match):
        decode_response(line, full_header=False)


def _with_fcs(body: bytes) -> bytes:
    return body + b"%02X" % fcs(body) + b"*\r"


def test_refused_and_malformed_responses() -> None:
    with pytest.raises(FrameError, match="refused with code 14"):
        decode_response(_with_fcs(b"@00FA14"), full_header=False)
    with pytest.raises(FrameError, match="not FA"):
        decode_response(_with_fcs(b"@00RD00400000000101"), full_header=False)
    with pytest.raises(FrameError, match="not decimal"):
        decode_response(_with_fcs(b"@0AFA00400000000101"), full_header=False)
    with pytest.raises(FrameError, match="not hexadecimal"):
        decode_response(_with_fcs(b"@00FA0040000000010"), full_header=False)
    with pytest.raises(FrameError, match="too short"):
        decode_response(_with_fcs(b"@00FA0040000000"), full_header=False)


def test_limits() -> None:
    biggest = CommandFrame(Header(FinsAddress(1, 5, 0), FinsAddress()), 0x01, 0x02, bytes(540))
    line = hostlink.encode_command(biggest)
    assert len(line) == hostlink.MAX_COMMAND_CHARS == 1114
    assert decode_command(line).frame == biggest
    with pytest.raises(CommandError, match="540"):
        hostlink.encode_command(CommandFrame(biggest.header, 0x01, 0x02, bytes(541)))
    reply = ResponseFrame.reply_to(biggest, 0, bytes(538))
    long_line = hostlink.encode_response(reply, full_header=True)
    assert len(long_line) == hostlink.MAX_RESPONSE_CHARS == 1115
    assert decode_response(long_line, full_header=True)[1].data == bytes(538)
    too_long = hostlink.encode_response(
        ResponseFrame.reply_to(biggest, 0, bytes(539)), full_header=True
    )
    with pytest.raises(FrameError, match="exceeds 1115"):
        decode_response(too_long, full_header=True)


def test_argument_checks() -> None:
    with pytest.raises(CommandError, match="unit number 32"):
        hostlink.encode_command(_direct_read(), unit=32)
    with pytest.raises(CommandError, match="wait time 16"):
        hostlink.encode_command(_direct_read(), wait_time=16)


def test_line_decoder_splits_and_discards_noise() -> None:
    decoder = LineDecoder()
    stream = b"\x00\xffnoise" + DIRECT_RESPONSE + NETWORK_COMMAND
    lines: list[bytes] = []
    for i in range(len(stream)):
        lines += decoder.feed(stream[i : i + 1])
    assert lines == [DIRECT_RESPONSE, NETWORK_COMMAND]
    assert decoder.discarded == 7


@pytest.mark.parametrize("cut", range(len(DIRECT_RESPONSE) * 2 + 1))
def test_line_decoder_any_split(cut: int) -> None:
    stream = DIRECT_RESPONSE * 2
    decoder = LineDecoder()
    assert decoder.feed(stream[:cut]) + decoder.feed(stream[cut:]) == [DIRECT_RESPONSE] * 2


def test_line_decoder_drops_over_long_lines() -> None:
    decoder = LineDecoder(max_chars=40)
    assert decoder.feed(DIRECT_RESPONSE) == []
    assert decoder.discarded == len(DIRECT_RESPONSE)
    assert decoder.feed(DIRECT_COMMAND) == [DIRECT_COMMAND]
    # A line that never ends is dropped once it is over the limit, not kept forever.
    assert decoder.feed(b"@" + b"0" * 100) == []
    assert decoder.feed(DIRECT_COMMAND) == [DIRECT_COMMAND]


def test_line_decoder_starts_a_line_at_the_last_at_sign() -> None:
    """A stray '@' (or a frame cut off half-way) swallowed the next command: the line ran
    from the first '@' and failed its FCS. '@' never occurs inside a frame."""
    decoder = LineDecoder()
    assert decoder.feed(b"@" + DIRECT_COMMAND) == [DIRECT_COMMAND]
    assert decoder.discarded == 1
    cut_off = NETWORK_COMMAND[:20]
    assert decoder.feed(cut_off + b"@@" + DIRECT_RESPONSE) == [DIRECT_RESPONSE]
    assert decoder.discarded == 1 + 22
    # byte by byte, the same
    decoder = LineDecoder()
    lines: list[bytes] = []
    for b in cut_off + b"@" + DIRECT_COMMAND:
        lines += decoder.feed(bytes((b,)))
    assert lines == [DIRECT_COMMAND]
    # bytes before a CR without any '@' are noise, not a line
    assert LineDecoder().feed(b"0E*\r" + DIRECT_COMMAND) == [DIRECT_COMMAND]


commands = st.builds(
    CommandFrame,
    st.builds(
        Header,
        st.builds(FinsAddress, st.integers(0, 127), st.integers(0, 255), st.integers(0, 255)),
        st.builds(FinsAddress, st.integers(0, 127), st.integers(0, 255), st.integers(0, 255)),
        sid=st.integers(0, 255),
    ),
    st.integers(0, 255),
    st.integers(0, 255),
    st.binary(max_size=540),
)


@given(commands, st.integers(0, 31), st.integers(0, 15))
def test_full_form_round_trip(frame: CommandFrame, unit: int, wait: int) -> None:
    line = hostlink.encode_command(frame, unit=unit, wait_time=wait, full_header=True)
    decoded = decode_command(line)
    assert (decoded.unit, decoded.wait_time, decoded.frame) == (unit, wait, frame)
    reply = ResponseFrame.reply_to(frame, 0x0080, frame.params[:538])
    assert decode_response(hostlink.encode_response(reply, full_header=True), full_header=True)[
        1
    ] == (reply)


_HEXISH = st.binary(max_size=60).map(lambda b: b.hex().upper().encode()) | st.text(
    "0123456789ABCDEFG@*", max_size=60
).map(str.encode)


@given(st.binary(max_size=80) | _HEXISH.map(lambda body: _with_fcs(b"@00FA" + body)))
def test_arbitrary_lines_raise_only_decode_errors(line: bytes) -> None:
    for decode in (
        decode_command,
        lambda raw: decode_response(raw, full_header=False),
        lambda raw: decode_response(raw, full_header=True),
    ):
        with contextlib.suppress(DecodeError):
            decode(line)
    decoder = LineDecoder(max_chars=50)
    for produced in decoder.feed(line):
        assert produced.startswith(b"@") and produced.endswith(b"\r")


_LINES = st.one_of(
    st.just(DIRECT_COMMAND),
    st.just(DIRECT_RESPONSE),
    st.just(NETWORK_COMMAND),
    st.builds(
        lambda frame, unit: hostlink.encode_command(frame, unit=unit, full_header=True),
        st.builds(
            CommandFrame,
            st.builds(
                Header,
                st.just(FinsAddress(1, 2, 0)),
                st.just(FinsAddress()),
                sid=st.integers(0, 255),
            ),
            st.integers(0, 255),
            st.integers(0, 255),
            st.binary(max_size=100),
        ),
        st.integers(0, 31),
    ),
)


@given(
    st.lists(st.tuples(st.binary(max_size=30), _LINES), max_size=6),
    st.lists(st.integers(0, 2000), max_size=8),
)
def test_line_decoder_finds_every_line_through_noise(
    parts: list[tuple[bytes, bytes]], cuts: list[int]
) -> None:
    """Whatever comes before a line (noise, '@'s, a cut-off frame) and however the stream is
    split, every line comes out whole; without a CR in the noise, nothing else does."""
    stream = b"".join(noise + line for noise, line in parts)
    decoder = LineDecoder()
    produced: list[bytes] = []
    start = 0
    for cut in [*sorted({c for c in cuts if c < len(stream)}), len(stream)]:
        produced += decoder.feed(stream[start:cut])
        start = cut
    expected = [line for _, line in parts]
    if not any(b"\r" in noise for noise, _ in parts):
        assert produced == expected
        assert decoder.discarded == sum(len(noise) for noise, _ in parts)
    else:  # a CR in the noise may end a garbage line of its own (refused later by its FCS)
        rest = iter(produced)
        assert all(any(line == got for got in rest) for line in expected)
    for line in produced:
        assert line.count(b"@") == 1 and line.startswith(b"@") and line.endswith(b"\r")
