"""FINS/TCP framing (W421 §7): a 16-byte header in front of every message.

::

    "FINS" | length (u32, bytes after this field) | command (u32) | error code (u32) | payload

Commands: 0 client node address send, 1 server node address send (reply), 2 FINS frame send,
3 FINS frame send error notification, 6 connection confirmation.

:class:`TcpClientConnection` is the client side of one connection, sans-IO (bytes in, events
out, as h11 and wsproto do it): the transport's asyncio and anyio pumps only move bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum, IntEnum

from .errors import FinsTcpError, FrameError
from .header import MAX_FRAME_SIZE

MAGIC = b"FINS"
TCP_HEADER_SIZE = 16
#: Largest value of the length field: 8 + a 2012-byte FINS frame (W421: 0x7E4 = 2020).
MAX_LENGTH = 8 + MAX_FRAME_SIZE
DEFAULT_PORT = 9600


#: FINS nodes a FINS/TCP handshake may name (client and server alike; 0 only asks the server
#: to allocate one, 255 is the broadcast node).
MIN_NODE, MAX_NODE = 1, 254


class TcpCommand(IntEnum):
    NODE_ADDRESS_REQUEST = 0
    NODE_ADDRESS_RESPONSE = 1
    FRAME = 2
    FRAME_ERROR = 3
    CONNECTION_CONFIRMATION = 6


class TcpErrorCode(IntEnum):
    NORMAL = 0x00
    BAD_HEADER = 0x01
    DATA_TOO_LONG = 0x02
    COMMAND_NOT_SUPPORTED = 0x03
    ALL_CONNECTIONS_IN_USE = 0x20
    NODE_ALREADY_CONNECTED = 0x21
    PROTECTED_NODE = 0x22
    CLIENT_NODE_OUT_OF_RANGE = 0x23
    SAME_NODE_ADDRESS = 0x24
    NO_NODE_AVAILABLE = 0x25


TCP_ERROR_MEANINGS: dict[int, str] = {
    0x00: "normal",
    0x01: "the header is not 'FINS' (ASCII)",
    0x02: "the data length is too long",
    0x03: "the command is not supported",
    0x20: "all connections are in use",
    0x21: "the specified node is already connected",
    0x22: "attempt to access a protected node from an unspecified IP address",
    0x23: "the client FINS node address is out of range",
    0x24: "the same FINS node address is being used by the client and server",
    0x25: "all the node addresses available for allocation have been used",
}


def tcp_error_meaning(code: int) -> str:
    return TCP_ERROR_MEANINGS.get(code, f"unknown FINS/TCP error code {code:#x}")


@dataclass(frozen=True, slots=True)
class TcpMessage:
    command: int
    error_code: int = 0
    payload: bytes = b""

    def encode(self) -> bytes:
        return encode_message(self.command, self.payload, self.error_code)


def encode_message(command: int, payload: bytes = b"", error_code: int = 0) -> bytes:
    length = 8 + len(payload)
    return (
        MAGIC
        + length.to_bytes(4, "big")
        + command.to_bytes(4, "big")
        + error_code.to_bytes(4, "big")
        + payload
    )


#: A command-2 header: magic, length, then command 2 and error code 0 as 8 fixed bytes.
_pack_frame_header = struct.Struct(">4sI8s").pack
_FRAME_COMMAND = (TcpCommand.FRAME << 32).to_bytes(8, "big")
_unpack_start = struct.Struct(">4sI").unpack_from
_unpack_header = struct.Struct(">4sIII").unpack_from
_FRAME = int(TcpCommand.FRAME)


def _check_start(magic: bytes, length: int, max_length: int) -> None:
    """Raise the error for a message start no stream can continue from, if it is one."""
    if magic != MAGIC:
        raise FinsTcpError("FINS/TCP header is not 'FINS'", tcp_error_code=TcpErrorCode.BAD_HEADER)
    if length < 8 or length > max_length:
        raise FinsTcpError(
            f"FINS/TCP length {length} out of range 8..{max_length}",
            tcp_error_code=TcpErrorCode.DATA_TOO_LONG,
        )


def encode_frame(fins_frame: bytes) -> bytes:
    """Wrap one FINS frame in a command-2 message (what :func:`encode_message` gives, faster)."""
    return _pack_frame_header(MAGIC, 8 + len(fins_frame), _FRAME_COMMAND) + fins_frame


def encode_frames(fins_frames: list[bytes]) -> bytes:
    """Several FINS frames as consecutive command-2 messages, in one bytes object."""
    head, magic, command = _pack_frame_header, MAGIC, _FRAME_COMMAND
    return b"".join([head(magic, 8 + len(frame), command) + frame for frame in fins_frames])


def encode_node_request(client_node: int = 0) -> bytes:
    """Client → server handshake; node 0 asks the server to allocate one."""
    if not 0 <= client_node <= 0xFE:
        raise FrameError(f"FINS/TCP client node {client_node} out of range 0..254")
    return encode_message(TcpCommand.NODE_ADDRESS_REQUEST, client_node.to_bytes(4, "big"))


def encode_node_response(client_node: int, server_node: int, error_code: int = 0) -> bytes:
    """Server → client handshake reply."""
    return encode_message(
        TcpCommand.NODE_ADDRESS_RESPONSE,
        client_node.to_bytes(4, "big") + server_node.to_bytes(4, "big"),
        error_code,
    )


def encode_error_notification(error_code: int) -> bytes:
    return encode_message(TcpCommand.FRAME_ERROR, b"", error_code)


def parse_node_request(message: TcpMessage) -> int:
    """The client node a command-0 message asks for (0 = allocate)."""
    if message.command != TcpCommand.NODE_ADDRESS_REQUEST or len(message.payload) != 4:
        raise FrameError("not a FINS/TCP node address request")
    return int.from_bytes(message.payload, "big")


def parse_node_response(message: TcpMessage, requested: int = 0) -> tuple[int, int]:
    """``(client_node, server_node)`` of a command-1 reply; :class:`FinsTcpError` if refused.

    Both nodes must be 1..254 and differ; a client node other than ``requested`` (when it is
    not 0, "allocate one") is refused too: :class:`FrameError` naming the field.
    """
    if message.command != TcpCommand.NODE_ADDRESS_RESPONSE:
        raise FrameError(f"expected FINS/TCP command 1, got {message.command}")
    if message.error_code:
        raise FinsTcpError(
            f"FINS/TCP handshake refused: {tcp_error_meaning(message.error_code)}",
            tcp_error_code=message.error_code,
        )
    if len(message.payload) != 8:
        raise FrameError(
            f"FINS/TCP node address reply has {len(message.payload)} payload bytes, expected 8"
        )
    client = int.from_bytes(message.payload[:4], "big")
    server = int.from_bytes(message.payload[4:], "big")
    for name, node in (("client", client), ("server", server)):
        if not MIN_NODE <= node <= MAX_NODE:
            raise FrameError(
                f"FINS/TCP node address reply names {name} node {node}, "
                f"out of range {MIN_NODE}..{MAX_NODE}"
            )
    if requested and client != requested:
        raise FrameError(
            f"FINS/TCP node address reply assigns client node {client}; node {requested} "
            "was asked for"
        )
    if client == server:
        raise FrameError(f"FINS/TCP node address reply gives client and server node {client}")
    return client, server


class TcpDecoder:
    """Incremental FINS/TCP stream decoder: feed it bytes as they arrive.

    Handles messages split across reads and several messages in one read. A bad magic or an
    impossible length raises :class:`FrameError` with ``tcp_error_code`` semantics in the
    message; the stream is unusable afterwards (the peer must close the connection, as the
    protocol says).
    """

    __slots__ = ("_buffer", "max_length")

    def __init__(self, max_length: int = MAX_LENGTH) -> None:
        self._buffer = bytearray()
        self.max_length = max_length

    @property
    def buffered(self) -> int:
        return len(self._buffer)

    def feed(self, data: bytes) -> list[TcpMessage]:
        """Every complete message in the bytes buffered so far (after adding ``data``)."""
        out: list[TcpMessage] = []
        append = out.append

        def frame(payload: bytes) -> None:
            append(TcpMessage(TcpCommand.FRAME, 0, payload))

        message = self.feed_frames(data, frame)
        while message is not None:
            append(message)
            message = self.feed_frames(b"", frame)
        return out

    def feed_frames(self, data: bytes, on_frame: Callable[[bytes], object]) -> TcpMessage | None:
        """Hand each complete FINS frame (command 2, error code 0) to ``on_frame``, in order.

        The receive path's fast form of :meth:`feed`: no message object per frame. Stops at
        the first complete message of another kind and returns it; the bytes after it
        stay buffered (call again with ``b""`` for them). Returns ``None`` when no complete
        message is left. A bad magic or length raises as in :meth:`feed`, after the frames
        before it were handed over.
        """
        buf = self._buffer
        if buf:  # the rest of an earlier read first (rare: reads mostly end on a message)
            buf += data
            data = bytes(buf)
            buf.clear()
        n = len(data)
        pos = 0
        found: TcpMessage | None = None
        max_length = self.max_length
        try:
            while n - pos >= 16:
                magic, length, command, error_code = _unpack_header(data, pos)
                if magic != MAGIC or length < 8 or length > max_length:
                    _check_start(magic, length, max_length)
                end = pos + 8 + length
                if end > n:
                    break
                payload = data[pos + 16 : end]
                pos = end
                if command == _FRAME and not error_code:
                    on_frame(payload)
                else:
                    found = TcpMessage(command, error_code, payload)
                    break
            else:
                if n - pos >= 8:  # a header's start: refuse a bad one before the rest comes
                    magic, length = _unpack_start(data, pos)
                    _check_start(magic, length, max_length)
        finally:
            if pos < n:
                buf += data[pos:] if pos else data
        return found


# --------------------------------------------------------------------------- the connection


class TcpConnectionState(Enum):
    """Where a client's FINS/TCP connection stands (transitions: :meth:`TcpClientConnection._to`).

    ::

        IDLE --start()--> AWAITING_NODE --node address reply--> OPEN
          any state --peer error, broken stream or close()--> CLOSED
    """

    #: Made, nothing sent yet: :meth:`TcpClientConnection.start` gives the node request.
    IDLE = "idle"
    #: Node address request sent; waiting for the server's reply (command 1).
    AWAITING_NODE = "awaiting node"
    #: Handshake done: both nodes known, FINS frames flow both ways.
    OPEN = "open"
    #: Over: the peer reported an error, broke the stream or refused the handshake, or we
    #: closed it. Nothing more is sent or received.
    CLOSED = "closed"


@dataclass(frozen=True, slots=True)
class NodeAssigned:
    """The handshake completed: our (client) node and the server's, both 1..254."""

    client_node: int
    server_node: int


@dataclass(frozen=True, slots=True)
class FrameReceived:
    """One whole FINS frame (10-byte header first) arrived in a command-2 message."""

    frame: bytes


@dataclass(frozen=True, slots=True)
class ConnectionConfirmed:
    """The server sent a connection confirmation (command 6); nothing to do about it."""


@dataclass(frozen=True, slots=True)
class PeerError:
    """The server reported a FINS/TCP error code (command 3, or a refused handshake): the
    connection is over."""

    #: The FINS/TCP error code (:class:`TcpErrorCode` for the known ones).
    code: int
    #: Whether it refused the handshake (a command-1 reply with an error code).
    refused: bool = False

    @property
    def meaning(self) -> str:
        """What the code means (W421), e.g. ``"all connections are in use"``."""
        return tcp_error_meaning(self.code)

    def error(self, where: str) -> FinsTcpError:
        """The exception a caller gets for it, naming the peer (``where``)."""
        what = "refused the FINS/TCP handshake" if self.refused else "reported a FINS/TCP error"
        return FinsTcpError(f"{where} {what}: {self.meaning}", tcp_error_code=self.code)


@dataclass(frozen=True, slots=True)
class MessageDiscarded:
    """A well-formed message the client has no use for after the handshake (another node
    address reply, a command-2 message with an error code, an unknown command): dropped,
    and worth counting."""

    command: int
    error_code: int

    @property
    def reason(self) -> str:
        return f"unexpected FINS/TCP command {self.command} (error code {self.error_code:#x})"


#: What :meth:`TcpClientConnection.receive_data` returns.
TcpEvent = NodeAssigned | FrameReceived | ConnectionConfirmed | PeerError | MessageDiscarded

_NO_EVENTS: tuple[TcpEvent, ...] = ()
_IDLE, _AWAITING, _OPEN, _CLOSED = (
    TcpConnectionState.IDLE,
    TcpConnectionState.AWAITING_NODE,
    TcpConnectionState.OPEN,
    TcpConnectionState.CLOSED,
)
_CONFIRMED = ConnectionConfirmed()


class TcpClientConnection:
    """The client side of one FINS/TCP connection, without I/O.

    ``start()`` gives the node address request to write; every byte read goes to
    :meth:`receive_data`, which returns the events it completes. A stream that cannot go on
    (bad magic or length, a handshake reply naming node 0 or 300, a FINS frame before the
    handshake, ...) raises :class:`FrameError` and closes the connection; an error the peer
    reports is a :class:`PeerError` event and closes it too. After the handshake, FINS frames
    can go straight to a callback (the receive path's fast form: no event object per frame).
    """

    __slots__ = ("_decoder", "client_node", "requested_node", "server_node", "state")

    def __init__(self, node: int = 0, *, max_length: int = MAX_LENGTH) -> None:
        if not 0 <= node <= MAX_NODE:
            raise FrameError(f"FINS/TCP client node {node} out of range 0..{MAX_NODE}")
        #: The client node asked for in the handshake (0: let the server allocate one).
        self.requested_node = node
        #: Our node and the server's, once the handshake assigned them.
        self.client_node: int | None = None
        self.server_node: int | None = None
        self.state = _IDLE
        self._decoder = TcpDecoder(max_length)

    def _to(self, state: TcpConnectionState) -> None:
        """The one place the state changes (forward only; CLOSED is final)."""
        current = self.state
        if current is _CLOSED or (state is not _CLOSED and state is not _NEXT[current]):
            raise FrameError(f"FINS/TCP connection cannot go from {current.value} to {state.value}")
        self.state = state

    def start(self) -> bytes:
        """The node address request to send first (IDLE -> AWAITING_NODE)."""
        self._to(_AWAITING)
        return encode_node_request(self.requested_node)

    def send_frame(self, frame: bytes) -> bytes:
        """The bytes that carry one FINS frame (only while OPEN)."""
        if self.state is not _OPEN:
            raise FrameError(f"cannot send a FINS frame: the connection is {self.state.value}")
        return encode_frame(frame)

    def close(self) -> None:
        """We ended the connection (CLOSED)."""
        if self.state is not _CLOSED:
            self._to(_CLOSED)

    def receive_data(
        self, data: bytes, on_frame: Callable[[bytes], object] | None = None
    ) -> Sequence[TcpEvent]:
        """The events completed by ``data`` (bytes read from the stream), in order.

        With ``on_frame``, FINS frames received while OPEN go to it, in order with the
        events, instead of becoming :class:`FrameReceived` events. Raises
        :class:`FrameError` (the connection is then CLOSED) for a stream that cannot go on.
        Events after a :class:`PeerError` are not decoded: it ends the connection.
        """
        if self.state is _OPEN and on_frame is not None:  # the receive path: frames only
            try:
                message = self._decoder.feed_frames(data, on_frame)
            except FrameError:
                self._to(_CLOSED)
                raise
            if message is None:
                return _NO_EVENTS
            return self._rest(message, on_frame)
        if self.state is _CLOSED:
            raise FrameError("the FINS/TCP connection is closed")
        if self.state is _IDLE:
            raise FrameError("FINS/TCP data arrived before the node address request was sent")
        events: list[TcpEvent] = []
        emit = on_frame or (lambda frame: events.append(FrameReceived(frame)))
        try:
            message = self._decoder.feed_frames(
                data, self._frame_before_handshake if self.state is _AWAITING else emit
            )
            while message is not None:
                event = self._message(message)
                events.append(event)
                if self.state is _CLOSED:
                    break
                message = self._decoder.feed_frames(
                    b"", emit if self.state is _OPEN else self._frame_before_handshake
                )
        except FrameError:
            self.close()
            raise
        return events

    def _rest(
        self, message: TcpMessage | None, on_frame: Callable[[bytes], object]
    ) -> list[TcpEvent]:
        """The events from ``message`` on, frames going to ``on_frame`` (OPEN)."""
        events: list[TcpEvent] = []
        try:
            while message is not None:
                events.append(self._message(message))
                if self.state is _CLOSED:
                    break
                message = self._decoder.feed_frames(b"", on_frame)
        except FrameError:
            self.close()
            raise
        return events

    @staticmethod
    def _frame_before_handshake(frame: bytes) -> None:
        raise FrameError("FINS/TCP server sent a FINS frame before its node address reply")

    def _message(self, message: TcpMessage) -> TcpEvent:
        """The event for one message other than a plain FINS frame; a protocol violation
        raises :class:`FrameError`."""
        command, code = message.command, message.error_code
        if command == TcpCommand.CONNECTION_CONFIRMATION:
            return _CONFIRMED
        if command == TcpCommand.FRAME_ERROR:
            self._to(_CLOSED)
            return PeerError(code)
        if self.state is _AWAITING:
            if command != TcpCommand.NODE_ADDRESS_RESPONSE:
                raise FrameError(
                    f"FINS/TCP server sent command {command} before its node address reply"
                )
            if code:
                self._to(_CLOSED)
                return PeerError(code, refused=True)
            self.client_node, self.server_node = parse_node_response(message, self.requested_node)
            self._to(_OPEN)
            return NodeAssigned(self.client_node, self.server_node)
        return MessageDiscarded(command, code)


#: The state after each one on the way to OPEN.
_NEXT = {_IDLE: _AWAITING, _AWAITING: _OPEN, _OPEN: _CLOSED, _CLOSED: _CLOSED}
