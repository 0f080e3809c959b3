"""FINS over Host Link (serial, ASCII): framing, FCS and the length limits (W342 §3-5).

Every byte of the FINS part travels as two uppercase hex characters. Command forms::

    short (directly connected CPU):  @ UU FA W  ICF DA2 SA2 SID  MRC SRC params  FCS * CR
    full  (network header):          @ UU FA W  ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2 SID
                                      MRC SRC params  FCS * CR

``UU`` is the Host Link unit number (2 decimal digits, 00-31), ``W`` the response wait time
in 10 ms units (one hex digit). Responses carry ``00`` where the command had ``W`` (a
Host-Link-level code; non-zero means the frame was refused) and the end code after the
command code. FCS is the XOR of every character from ``@`` to the last text character.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import CommandError, FrameError
from .header import CommandFrame, FinsAddress, Header, ResponseFrame

TERMINATOR = b"*\r"
#: Longest command frame in characters (full header with 540 parameter bytes).
MAX_COMMAND_CHARS = 1114
#: Longest response frame in characters.
MAX_RESPONSE_CHARS = 1115
#: Parameter bytes after the command code in one command (1,080 characters).
MAX_PARAMETER_BYTES = 540
#: Data bytes after the end code in one response (1,076 characters).
MAX_RESPONSE_DATA_BYTES = 538

_HEX = b"0123456789ABCDEF"


def fcs(chars: bytes) -> int:
    """The Host Link frame check sequence: XOR of every character."""
    value = 0
    for c in chars:
        value ^= c
    return value


def _hex(data: bytes) -> bytes:
    return data.hex().upper().encode("ascii")


def _unhex(chars: bytes, what: str) -> bytes:
    try:
        return bytes.fromhex(chars.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        raise FrameError(f"Host Link {what} is not hexadecimal: {chars[:40]!r}") from None


def _check_and_strip(line: bytes, max_chars: int) -> bytes:
    """Verify '@', FCS and terminator; return the characters between '@' and the FCS."""
    if line.endswith(b"\r") and not line.endswith(TERMINATOR):
        raise FrameError("Host Link frame lacks the '*' terminator")
    if not line.endswith(TERMINATOR):
        raise FrameError("Host Link frame lacks its '*' CR terminator")
    if len(line) > max_chars:
        raise FrameError(f"Host Link frame of {len(line)} characters exceeds {max_chars}")
    if not line.startswith(b"@") or len(line) < 9:
        raise FrameError("Host Link frame does not start with '@' or is too short")
    body, fcs_chars = line[:-4], line[-4:-2]
    try:
        received = int(fcs_chars.decode("ascii"), 16)
    except (UnicodeDecodeError, ValueError):
        raise FrameError(f"Host Link FCS {fcs_chars!r} is not hexadecimal") from None
    expected = fcs(body)
    if received != expected:
        raise FrameError(
            f"Host Link FCS mismatch: received {received:02X}, computed {expected:02X}"
        )
    return body[1:]


def _unit_chars(unit: int) -> bytes:
    if not 0 <= unit <= 31:
        raise CommandError(f"Host Link unit number {unit} out of range 0..31")
    return b"%02d" % unit


def _parse_unit(chars: bytes) -> int:
    if not chars.isdigit():
        raise FrameError(f"Host Link unit number {chars!r} is not decimal")
    return int(chars)


def encode_command(
    frame: CommandFrame, *, unit: int = 0, wait_time: int = 0, full_header: bool | None = None
) -> bytes:
    """Encode a FINS command as a Host Link line (with FCS and ``*`` CR).

    ``full_header`` defaults to the short form when the destination is the directly
    connected CPU (network 0, node 0) and to the full form otherwise.
    """
    if not 0 <= wait_time <= 0xF:
        raise CommandError(f"Host Link response wait time {wait_time} out of range 0..15")
    if len(frame.params) > MAX_PARAMETER_BYTES:
        raise CommandError(
            f"{len(frame.params)} parameter bytes exceed the Host Link limit "
            f"of {MAX_PARAMETER_BYTES}"
        )
    h = frame.header
    if full_header is None:
        full_header = h.destination.network != 0 or h.destination.node != 0
    if full_header:
        fins = h.encode()
    else:
        fins = bytes((0x00, h.destination.unit, h.source.unit, h.sid))
    body = (
        b"@"
        + _unit_chars(unit)
        + b"FA"
        + _HEX[wait_time : wait_time + 1]
        + _hex(fins + bytes((frame.mrc, frame.src)) + frame.params)
    )
    return body + b"%02X" % fcs(body) + TERMINATOR


@dataclass(frozen=True, slots=True)
class HostLinkCommand:
    """A decoded Host Link FINS command (server side)."""

    unit: int
    wait_time: int
    full_header: bool
    frame: CommandFrame


def decode_command(line: bytes) -> HostLinkCommand:
    """Decode a Host Link FINS command line; :class:`FrameError` on any framing fault."""
    body = _check_and_strip(line, MAX_COMMAND_CHARS)
    unit = _parse_unit(body[0:2])
    if body[2:4] != b"FA":
        raise FrameError(f"Host Link header code {body[2:4]!r} is not FA")
    wait = body[4:5]
    if wait not in [bytes((c,)) for c in _HEX]:
        raise FrameError(f"Host Link response wait time {wait!r} is not a hex digit")
    raw = _unhex(body[5:], "command")
    if len(raw) < 2:
        raise FrameError("Host Link FINS command too short")
    full = bool(raw[0] & 0x80)
    if full:
        if len(raw) < 12:
            raise FrameError("Host Link FINS command too short for a full header")
        frame = CommandFrame.decode(raw)
    else:
        if len(raw) < 6:
            raise FrameError("Host Link FINS command too short for the short header")
        header = Header(
            FinsAddress(0, 0, raw[1]), FinsAddress(0, 0, raw[2]), sid=raw[3], icf=raw[0], gct=0
        )
        frame = CommandFrame(header, raw[4], raw[5], raw[6:])
    if len(frame.params) > MAX_PARAMETER_BYTES:
        raise FrameError(f"{len(frame.params)} parameter bytes exceed the Host Link limit")
    return HostLinkCommand(unit, int(wait, 16), full, frame)


def encode_response(
    response: ResponseFrame, *, unit: int = 0, full_header: bool = False, hostlink_code: int = 0
) -> bytes:
    """Encode a FINS response as a Host Link line (server side)."""
    raw = response.encode()
    fins = raw if full_header else bytes((raw[0], raw[5], raw[8], raw[9])) + raw[10:]
    body = b"@" + _unit_chars(unit) + b"FA" + b"%02X" % hostlink_code + _hex(fins)
    return body + b"%02X" % fcs(body) + TERMINATOR


def decode_response(line: bytes, *, full_header: bool) -> tuple[int, ResponseFrame]:
    """Decode a Host Link FINS response line into ``(unit, response)``.

    Raises :class:`FrameError` on a bad FCS, a non-``00`` Host Link code or malformed text.
    """
    body = _check_and_strip(line, MAX_RESPONSE_CHARS)
    unit = _parse_unit(body[0:2])
    if body[2:4] != b"FA":
        raise FrameError(f"Host Link header code {body[2:4]!r} is not FA")
    code = body[4:6]
    if code != b"00":
        raise FrameError(f"Host Link frame refused with code {code.decode('ascii', 'replace')}")
    raw = _unhex(body[6:], "response")
    if full_header:
        return unit, ResponseFrame.decode(raw)
    if len(raw) < 8:
        raise FrameError("Host Link FINS response too short")
    # Rebuild a 10-byte header so that the one response parser serves both forms.
    binary = bytes((raw[0], 0, 0, 0, 0, raw[1], 0, 0, raw[2], raw[3])) + raw[4:]
    return unit, ResponseFrame.decode(binary)


class LineDecoder:
    """Splits a serial byte stream into Host Link lines (``@`` … CR).

    A line starts at the *last* ``@`` before its CR: ``@`` never occurs inside a frame (only
    hex digits, ``*`` and CR follow it), so an ``@`` means a new frame begins and whatever came
    before it (noise, a stray ``@``, a frame cut off by a reset) is dropped rather than glued
    in front of the next command. Dropped bytes are counted in ``discarded``; a line longer
    than ``max_chars`` is discarded whole, and so are bytes before a CR with no ``@``.
    """

    __slots__ = ("_buffer", "discarded", "max_chars")

    def __init__(self, max_chars: int = MAX_RESPONSE_CHARS) -> None:
        self._buffer = bytearray()
        self.max_chars = max_chars
        self.discarded = 0

    def feed(self, data: bytes) -> list[bytes]:
        buf = self._buffer
        buf += data
        lines: list[bytes] = []
        while True:
            end = buf.find(b"\r")
            if end < 0:
                # no line complete yet: keep what follows the last '@', within the limit
                start = buf.rfind(b"@")
                drop = len(buf) if start < 0 or len(buf) - start > self.max_chars else start
                if drop:
                    self.discarded += drop
                    del buf[:drop]
                return lines
            start = buf.rfind(b"@", 0, end)
            if start < 0:
                self.discarded += end + 1
                del buf[: end + 1]
                continue
            line = bytes(buf[start : end + 1])
            self.discarded += start
            del buf[: end + 1]
            if len(line) > self.max_chars:
                self.discarded += len(line)
                continue
            lines.append(line)
