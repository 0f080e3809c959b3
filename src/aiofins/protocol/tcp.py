"""FINS/TCP framing (W421 §7): a 16-byte header in front of every message.

::

    "FINS" | length (u32, bytes after this field) | command (u32) | error code (u32) | payload

Commands: 0 client node address send, 1 server node address send (reply), 2 FINS frame send,
3 FINS frame send error notification, 6 connection confirmation.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

from .errors import FinsTcpError, FrameError
from .header import MAX_FRAME_SIZE

MAGIC = b"FINS"
TCP_HEADER_SIZE = 16
#: Largest value of the length field: 8 + a 2012-byte FINS frame (W421: 0x7E4 = 2020).
MAX_LENGTH = 8 + MAX_FRAME_SIZE
DEFAULT_PORT = 9600


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


def parse_node_response(message: TcpMessage) -> tuple[int, int]:
    """``(client_node, server_node)`` of a command-1 reply; :class:`FinsTcpError` if refused."""
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
    return (int.from_bytes(message.payload[:4], "big"), int.from_bytes(message.payload[4:], "big"))


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
