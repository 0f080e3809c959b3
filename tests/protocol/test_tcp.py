"""FINS/TCP framing (W421 §7, wire-format §3 and §8.2) and the incremental stream decoder."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol import tcp
from aiofins.protocol.errors import DecodeError, FinsTcpError, FrameError
from aiofins.protocol.header import CommandFrame, ResponseFrame
from aiofins.protocol.tcp import TcpCommand, TcpDecoder, TcpErrorCode, TcpMessage

# Wire-format 8.2, byte for byte.
HELLO = bytes.fromhex("46494E53 0000000C 00000000 00000000 00000000")
WELCOME = bytes.fromhex("46494E53 00000010 00000001 00000000 000000EF 0000000A")
READ = bytes.fromhex("46494E53 0000001A 00000002 00000000 800002000A0000EF0002 0101 82006400000A")
READ_REPLY = bytes.fromhex(
    "46494E53 0000002A 00000002 00000000 C0000200EF00000A0002 0101 0000"
    "0001 0002 0003 0004 0005 0006 0007 0008 0009 000A"
)
REFUSED = bytes.fromhex("46494E53 00000010 00000001 00000020 00000000 00000000")


def test_worked_example_sizes() -> None:
    assert (len(HELLO), len(WELCOME), len(READ), len(READ_REPLY)) == (20, 24, 34, 50)


def test_handshake_bytes() -> None:
    assert tcp.encode_node_request(0) == HELLO
    assert tcp.encode_node_response(0xEF, 0x0A) == WELCOME
    hello, welcome = TcpDecoder().feed(HELLO + WELCOME)
    assert hello == TcpMessage(TcpCommand.NODE_ADDRESS_REQUEST, 0, bytes(4))
    assert tcp.parse_node_request(hello) == 0
    assert tcp.parse_node_response(welcome) == (0xEF, 0x0A)
    assert tcp.encode_node_request(0x22)[-4:] == bytes.fromhex("00000022")


def test_frame_bytes() -> None:
    fins = READ[16:]
    assert tcp.encode_frame(fins) == READ
    assert TcpMessage(TcpCommand.FRAME, 0, fins).encode() == READ
    (message,) = TcpDecoder().feed(READ)
    assert message.command == TcpCommand.FRAME and message.error_code == 0
    command = CommandFrame.decode(message.payload)
    assert command.header.source.node == 0xEF and command.header.destination.node == 0x0A
    assert command.header.sid == 2
    reply = ResponseFrame.reply_to(command, 0, b"".join(n.to_bytes(2, "big") for n in range(1, 11)))
    assert tcp.encode_frame(reply.encode()) == READ_REPLY


def test_refusal_raises_fins_tcp_error() -> None:
    (message,) = TcpDecoder().feed(REFUSED)
    with pytest.raises(FinsTcpError, match="all connections are in use") as info:
        tcp.parse_node_response(message)
    assert info.value.tcp_error_code == TcpErrorCode.ALL_CONNECTIONS_IN_USE
    assert int(TcpErrorCode.ALL_CONNECTIONS_IN_USE) == 0x20


def test_error_notification_and_connection_confirmation() -> None:
    notice = tcp.encode_error_notification(TcpErrorCode.COMMAND_NOT_SUPPORTED)
    assert notice == bytes.fromhex("46494E53 00000008 00000003 00000003")
    confirm = tcp.encode_message(TcpCommand.CONNECTION_CONFIRMATION)
    assert confirm == bytes.fromhex("46494E53 00000008 00000006 00000000")
    first, second = TcpDecoder().feed(notice + confirm)
    assert (first.command, first.error_code, first.payload) == (3, 3, b"")
    assert (second.command, second.error_code) == (6, 0)


def test_tcp_error_meanings() -> None:
    for code in TcpErrorCode:
        assert tcp.tcp_error_meaning(code)
    assert tcp.tcp_error_meaning(0x99) == "unknown FINS/TCP error code 0x99"


def test_handshake_parse_errors() -> None:
    with pytest.raises(FrameError):
        tcp.parse_node_request(TcpMessage(TcpCommand.FRAME, 0, bytes(4)))
    with pytest.raises(FrameError):
        tcp.parse_node_request(TcpMessage(TcpCommand.NODE_ADDRESS_REQUEST, 0, bytes(3)))
    with pytest.raises(FrameError, match="expected FINS/TCP command 1"):
        tcp.parse_node_response(TcpMessage(TcpCommand.FRAME, 0, bytes(8)))
    with pytest.raises(FrameError, match="payload bytes"):
        tcp.parse_node_response(TcpMessage(TcpCommand.NODE_ADDRESS_RESPONSE, 0, bytes(4)))
    with pytest.raises(FrameError):
        tcp.encode_node_request(0xFF)


STREAM = HELLO + WELCOME + READ + READ_REPLY + REFUSED
EXPECTED = [TcpDecoder().feed(part)[0] for part in (HELLO, WELCOME, READ, READ_REPLY, REFUSED)]


@pytest.mark.parametrize("cut", range(1, len(STREAM)))
def test_split_at_every_byte_boundary(cut: int) -> None:
    decoder = TcpDecoder()
    messages = decoder.feed(STREAM[:cut]) + decoder.feed(STREAM[cut:])
    assert messages == EXPECTED
    assert decoder.buffered == 0


def test_one_byte_at_a_time() -> None:
    decoder = TcpDecoder()
    messages: list[TcpMessage] = []
    for i in range(len(STREAM)):
        messages += decoder.feed(STREAM[i : i + 1])
    assert messages == EXPECTED


messages_st = st.lists(
    st.builds(
        TcpMessage,
        st.sampled_from([0, 1, 2, 3, 6]),
        st.integers(0, 0xFFFFFFFF),
        st.binary(max_size=300),
    ),
    max_size=8,
)


@given(messages_st, st.data())
def test_any_split_and_merge(messages: list[TcpMessage], data: st.DataObject) -> None:
    stream = b"".join(m.encode() for m in messages)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    decoder = TcpDecoder()
    out: list[TcpMessage] = []
    start = 0
    for cut in [*cuts, len(stream)]:
        out += decoder.feed(stream[start:cut])
        start = cut
    assert out == messages
    assert decoder.buffered == 0


frames_and_others_st = st.lists(
    st.builds(
        TcpMessage,
        st.sampled_from([2, 2, 2, 0, 1, 3, 6]),
        st.one_of(st.just(0), st.integers(0, 0xFFFFFFFF)),
        st.binary(max_size=300),
    ),
    max_size=12,
)


@given(frames_and_others_st, st.data())
def test_feed_frames_hands_over_the_same_messages_in_order(
    messages: list[TcpMessage], data: st.DataObject
) -> None:
    """The receive path's form: frames to the callback, anything else returned, in order."""
    stream = b"".join(m.encode() for m in messages)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    decoder = TcpDecoder()
    out: list[TcpMessage] = []

    def frame(payload: bytes) -> None:
        out.append(TcpMessage(TcpCommand.FRAME, 0, payload))

    start = 0
    for cut in [*cuts, len(stream)]:
        message = decoder.feed_frames(stream[start:cut], frame)
        while message is not None:
            assert not (message.command == TcpCommand.FRAME and message.error_code == 0)
            out.append(message)
            message = decoder.feed_frames(b"", frame)
        start = cut
    assert out == messages
    assert decoder.buffered == 0


@given(st.lists(st.binary(min_size=10, max_size=2012), max_size=8))
def test_encode_frames_is_the_messages_of_encode_frame_in_order(frames: list[bytes]) -> None:
    data = tcp.encode_frames(frames)
    assert data == b"".join(tcp.encode_frame(frame) for frame in frames)
    out: list[bytes] = []
    assert TcpDecoder().feed_frames(data, out.append) is None
    assert out == frames


def test_a_bad_header_start_is_refused_before_the_rest_of_it_arrives() -> None:
    """8 bytes are enough to see a wrong magic or an impossible length."""
    with pytest.raises(FinsTcpError, match="not 'FINS'"):
        TcpDecoder().feed_frames(b"HTTP/1.1", lambda frame: None)
    with pytest.raises(FinsTcpError, match="length 7"):
        TcpDecoder().feed_frames(b"FINS\x00\x00\x00\x07", lambda frame: None)
    decoder = TcpDecoder()  # a good start waits for the rest
    assert decoder.feed_frames(tcp.encode_frame(b"x" * 10)[:15], lambda frame: None) is None
    assert decoder.buffered == 15


def test_feed_frames_hands_over_the_frames_before_a_bad_header() -> None:
    frames: list[bytes] = []
    decoder = TcpDecoder()
    with pytest.raises(FinsTcpError) as info:
        decoder.feed_frames(
            tcp.encode_frame(b"one") + tcp.encode_frame(b"two") + b"JUNK" * 4, frames.append
        )
    assert frames == [b"one", b"two"]
    assert info.value.tcp_error_code == TcpErrorCode.BAD_HEADER


def test_largest_frame_and_one_byte_more() -> None:
    biggest = tcp.encode_frame(bytes(2012))
    assert biggest[4:8] == (2020).to_bytes(4, "big")  # 0x7E4
    assert TcpDecoder().feed(biggest)[0].payload == bytes(2012)
    with pytest.raises(FinsTcpError, match="length 2021") as info:
        TcpDecoder().feed(tcp.encode_frame(bytes(2013)))
    assert info.value.tcp_error_code == TcpErrorCode.DATA_TOO_LONG


def test_bad_magic() -> None:
    decoder = TcpDecoder()
    assert decoder.feed(HELLO) != []
    with pytest.raises(FinsTcpError, match="not 'FINS'") as info:
        decoder.feed(b"HTTP/1.1 200 OK\r\n")
    assert info.value.tcp_error_code == TcpErrorCode.BAD_HEADER


def test_short_length_field() -> None:
    with pytest.raises(FinsTcpError):
        TcpDecoder().feed(b"FINS\x00\x00\x00\x07" + bytes(8))


def test_waits_for_the_rest() -> None:
    decoder = TcpDecoder()
    assert decoder.feed(READ[:7]) == []  # not even the length yet
    assert decoder.feed(READ[7:20]) == []
    assert decoder.buffered == 20
    assert len(decoder.feed(READ[20:])) == 1


@given(st.binary(max_size=200), st.integers(1, 50))
def test_arbitrary_bytes_raise_only_aiofins_errors(raw: bytes, chunk: int) -> None:
    decoder = TcpDecoder()
    try:
        for i in range(0, len(raw), chunk):
            for message in decoder.feed(raw[i : i + chunk]):
                if message.command == TcpCommand.NODE_ADDRESS_RESPONSE:
                    tcp.parse_node_response(message)
                elif message.command == TcpCommand.FRAME:
                    ResponseFrame.decode(message.payload)
    except DecodeError:
        pass


@given(st.binary(max_size=64))
def test_arbitrary_payload_after_valid_envelope(payload: bytes) -> None:
    (message,) = TcpDecoder().feed(tcp.encode_frame(payload))
    assert message.payload == payload
    for parse in (tcp.parse_node_request, tcp.parse_node_response):
        try:
            parse(TcpMessage(0, 0, payload))
            parse(TcpMessage(1, 0, payload))
        except DecodeError:
            pass


def _reference(stream: bytes, max_length: int) -> tuple[list[TcpMessage], int | None, int]:
    """What a decoder owes for ``stream`` as a whole: its messages up to the first start no
    stream can continue from (a wrong magic or length once 8 bytes of it are there), that
    start's offset (``None``: none) and the bytes it then holds."""
    out: list[TcpMessage] = []
    pos = 0
    while len(stream) - pos >= 8:
        magic, length = stream[pos : pos + 4], int.from_bytes(stream[pos + 4 : pos + 8], "big")
        if magic != tcp.MAGIC or not 8 <= length <= max_length:
            return out, pos, len(stream) - pos
        end = pos + 8 + length
        if end > len(stream):
            break
        command = int.from_bytes(stream[pos + 8 : pos + 12], "big")
        error_code = int.from_bytes(stream[pos + 12 : pos + 16], "big")
        out.append(TcpMessage(command, error_code, stream[pos + 16 : end]))
        pos = end
    return out, None, len(stream) - pos


def _damaged(message: bytes, how: int, value: int) -> bytes:
    if how == 1:  # a wrong magic
        return b"FINs" + message[4:]
    if how == 2:  # a length out of range (0..7 or above the largest)
        return message[:4] + value.to_bytes(4, "big") + message[8:]
    return message


damaged_stream_st = st.lists(
    st.tuples(
        st.builds(
            TcpMessage,
            st.sampled_from([2, 2, 2, 0, 1, 3, 6]),
            st.one_of(st.just(0), st.integers(0, 0xFFFFFFFF)),
            st.binary(max_size=40),
        ),
        st.sampled_from([0, 0, 0, 0, 0, 0, 1, 2]),
        st.one_of(st.integers(0, 7), st.integers(49, 0xFFFFFFFF)),
    ),
    max_size=8,
).map(lambda parts: b"".join(_damaged(m.encode(), how, v) for m, how, v in parts))


@given(damaged_stream_st, st.data(), st.sampled_from([tcp.MAX_LENGTH, 48, 20]))
def test_feed_frames_against_a_reference_with_damage_and_max_length(
    stream: bytes, data: st.DataObject, max_length: int
) -> None:
    """Any split, any damage: the same messages as the whole stream gives, in order; the
    error as soon as the 8 bytes of a bad start are there (not only once 16 are), with every
    message before it handed over; the bad bytes kept and refused again on every later call."""
    expected, bad_at, left = _reference(stream, max_length)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=12)))
    decoder = TcpDecoder(max_length)
    out: list[TcpMessage] = []

    def frame(payload: bytes) -> None:
        out.append(TcpMessage(TcpCommand.FRAME, 0, payload))

    start = 0
    for cut in [*cuts, len(stream)]:
        try:
            message = decoder.feed_frames(stream[start:cut], frame)
            while message is not None:
                out.append(message)
                message = decoder.feed_frames(b"", frame)
        except FinsTcpError as exc:
            assert bad_at is not None and cut - bad_at >= 8  # not before the 8 bytes came
            assert out == expected
            assert exc.tcp_error_code in (TcpErrorCode.BAD_HEADER, TcpErrorCode.DATA_TOO_LONG)
            assert decoder.buffered == cut - bad_at
            with pytest.raises(FinsTcpError):
                decoder.feed_frames(b"", frame)
            return
        assert bad_at is None or cut - bad_at < 8  # ... and not after either
        start = cut
    assert bad_at is None
    assert out == expected
    assert decoder.buffered == left


# ------------------------------------------------------------- the sans-IO client connection


def _state(conn: tcp.TcpClientConnection) -> tcp.TcpConnectionState:
    """The state now (a call, so that mypy does not keep an earlier assertion's narrowing)."""
    return conn.state


def _open_connection(node: int = 0) -> tcp.TcpClientConnection:
    conn = tcp.TcpClientConnection(node)
    assert conn.start() == tcp.encode_node_request(node)
    assert conn.state is tcp.TcpConnectionState.AWAITING_NODE
    return conn


def test_connection_handshake_and_frames_as_events() -> None:
    conn = tcp.TcpClientConnection()
    assert conn.state is tcp.TcpConnectionState.IDLE
    assert conn.start() == HELLO
    events = conn.receive_data(WELCOME + tcp.encode_message(6) + READ_REPLY)
    assert list(events) == [
        tcp.NodeAssigned(0xEF, 0x0A),
        tcp.ConnectionConfirmed(),
        tcp.FrameReceived(READ_REPLY[16:]),
    ]
    assert _state(conn) is tcp.TcpConnectionState.OPEN
    assert (conn.client_node, conn.server_node) == (0xEF, 0x0A)
    assert conn.send_frame(READ[16:]) == READ


def test_connection_fast_path_hands_frames_to_the_callback() -> None:
    conn = _open_connection()
    conn.receive_data(WELCOME)
    frames: list[bytes] = []
    two = READ_REPLY + READ_REPLY
    assert conn.receive_data(two[:30], frames.append) == ()
    assert conn.receive_data(two[30:], frames.append) == ()
    assert frames == [READ_REPLY[16:]] * 2
    odd = tcp.encode_message(2, b"x" * 10, 5) + tcp.encode_message(1, bytes(8))
    events = conn.receive_data(odd + READ_REPLY, frames.append)
    assert [e.reason for e in events if isinstance(e, tcp.MessageDiscarded)] == [
        "unexpected FINS/TCP command 2 (error code 0x5)",
        "unexpected FINS/TCP command 1 (error code 0x0)",
    ]
    assert len(frames) == 3


@pytest.mark.parametrize(
    ("client", "server", "requested", "match"),
    [
        (0, 10, 0, "client node 0, out of range 1..254"),
        (300, 10, 0, "client node 300, out of range 1..254"),
        (255, 10, 0, "client node 255"),
        (5, 0, 0, "server node 0, out of range"),
        (5, 255, 0, "server node 255, out of range"),
        (7, 10, 5, "assigns client node 7; node 5 was asked for"),
        (10, 10, 0, "client and server node 10"),
    ],
)
def test_connection_refuses_a_handshake_reply_with_bad_nodes(
    client: int, server: int, requested: int, match: str
) -> None:
    conn = _open_connection(requested)
    reply = tcp.encode_message(1, client.to_bytes(4, "big") + server.to_bytes(4, "big"))
    with pytest.raises(FrameError, match=match):
        conn.receive_data(reply)
    assert conn.state is tcp.TcpConnectionState.CLOSED
    with pytest.raises(FrameError, match="closed"):
        conn.receive_data(READ_REPLY)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (READ_REPLY, "FINS frame before its node address reply"),
        (tcp.encode_message(0, bytes(4)), "command 0 before its node address reply"),
        (tcp.encode_message(9), "command 9 before its node address reply"),
        (tcp.encode_message(1, bytes(4)), "4 payload bytes, expected 8"),
        (b"FINZ" + WELCOME[4:], "not 'FINS'"),
        (WELCOME[:4] + bytes.fromhex("00000007") + WELCOME[8:], "length 7 out of range"),
    ],
)
def test_connection_refuses_what_breaks_the_handshake(data: bytes, match: str) -> None:
    conn = _open_connection()
    with pytest.raises(FrameError, match=match):
        conn.receive_data(data)
    assert conn.state is tcp.TcpConnectionState.CLOSED


def test_peer_errors_are_events_that_close_the_connection() -> None:
    conn = _open_connection()
    (refused,) = conn.receive_data(REFUSED)
    assert refused == tcp.PeerError(0x20, refused=True)
    assert isinstance(refused, tcp.PeerError)
    assert refused.meaning == "all connections are in use"
    error = refused.error("tcp://plc:9600")
    assert isinstance(error, FinsTcpError) and error.tcp_error_code == 0x20
    assert str(error) == "tcp://plc:9600 refused the FINS/TCP handshake: all connections are in use"
    assert conn.state is tcp.TcpConnectionState.CLOSED

    conn = _open_connection()
    notice = tcp.encode_error_notification(TcpErrorCode.COMMAND_NOT_SUPPORTED)
    events = conn.receive_data(WELCOME + notice + READ_REPLY, lambda f: None)
    assert list(events) == [tcp.NodeAssigned(0xEF, 0x0A), tcp.PeerError(3)]
    assert events[1].meaning == "the command is not supported"  # type: ignore[union-attr]
    assert conn.state is tcp.TcpConnectionState.CLOSED


def test_connection_refuses_steps_out_of_order() -> None:
    conn = tcp.TcpClientConnection()
    with pytest.raises(FrameError, match="before the node address request was sent"):
        conn.receive_data(WELCOME)
    conn = tcp.TcpClientConnection()
    with pytest.raises(FrameError, match="cannot send a FINS frame: the connection is idle"):
        conn.send_frame(READ[16:])
    conn.start()
    with pytest.raises(FrameError, match="from awaiting node to awaiting node"):
        conn.start()
    conn.close()
    conn.close()  # idempotent
    with pytest.raises(FrameError):
        conn.start()
    with pytest.raises(FrameError, match=r"out of range 0\.\.254"):
        tcp.TcpClientConnection(255)


def _splits(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    return [data[a:b] for a, b in zip([0, *points], [*points, len(data)], strict=True)]


@given(st.binary(max_size=300), st.lists(st.integers(0, 10_000), max_size=8), st.booleans())
def test_connection_never_raises_but_frame_error_on_arbitrary_bytes(
    data: bytes, cuts: list[int], handshaken: bool
) -> None:
    conn = _open_connection()
    if handshaken:
        conn.receive_data(WELCOME)
    for chunk in _splits(data, cuts):
        try:
            events = conn.receive_data(chunk, (lambda f: None) if handshaken else None)
        except FrameError:
            assert conn.state is tcp.TcpConnectionState.CLOSED
            return
        for event in events:
            assert isinstance(
                event,
                tcp.NodeAssigned
                | tcp.FrameReceived
                | tcp.ConnectionConfirmed
                | tcp.PeerError
                | tcp.MessageDiscarded,
            )
            if isinstance(event, tcp.NodeAssigned):
                assert 1 <= event.client_node <= 254 and 1 <= event.server_node <= 254
        if conn.state is tcp.TcpConnectionState.CLOSED:
            return


_MESSAGES = st.one_of(
    st.builds(lambda f: tcp.encode_message(2, f), st.binary(min_size=10, max_size=40)),
    st.builds(lambda c: tcp.encode_message(c), st.sampled_from([6, 7, 1, 0])),
)


@given(st.lists(_MESSAGES, max_size=10), st.lists(st.integers(0, 10_000), max_size=10))
def test_connection_events_do_not_depend_on_how_the_stream_is_split(
    messages: list[bytes], cuts: list[int]
) -> None:
    stream = WELCOME + b"".join(messages)
    whole = _open_connection()
    expected = list(whole.receive_data(stream))
    split = _open_connection()
    got = [event for chunk in _splits(stream, cuts) for event in split.receive_data(chunk)]
    assert got == expected
    assert expected[0] == tcp.NodeAssigned(0xEF, 0x0A)
    assert len(expected) == 1 + len(messages)
