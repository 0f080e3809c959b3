"""The 10-byte FINS header and whole command/response frames.

Command frame::

    ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2 SID MRC SRC [parameters...]

Response frame::

    ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2 SID MRC SRC MRES SRES [relay trailer] [data...]

ICF bit 7 = gateway (always set when sending), bit 6 = response, bit 0 = no response
wanted. A response swaps the destination and source addresses of its command and echoes
RSV, SID and the command code. When bit 15 of the end code (relay error) is set, two bytes
follow the end code: the network and node of the relay point that failed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .endcodes import EndCode
from .errors import CommandError, FrameError

HEADER_SIZE = 10
COMMAND_CODE_SIZE = 2
END_CODE_SIZE = 2
#: Largest FINS frame on Ethernet/Controller Link (10 header + 2 command code + 2000).
MAX_FRAME_SIZE = 2012
#: Largest parameter block after the command code.
MAX_PARAMETER_SIZE = 2000
#: Largest response data after the end code.
MAX_RESPONSE_DATA_SIZE = 1998

ICF_GATEWAY = 0x80
ICF_RESPONSE = 0x40
ICF_NO_RESPONSE = 0x01

#: The classic permissible gateway count; 0x07 for v2.0+ CPUs routing over > 3 levels.
DEFAULT_GCT = 0x02

DA2_CPU_UNIT = 0x00
DA2_INNER_BOARD = 0xE1
DA2_NETWORK_UNIT = 0xFE


@dataclass(frozen=True, slots=True)
class FinsAddress:
    """A FINS node address: network (0 = local, 1-127), node (0-255) and unit (0-255)."""

    network: int = 0
    node: int = 0
    unit: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.network <= 0x7F:
            raise CommandError(f"network address {self.network} out of range 0..127")
        if not 0 <= self.node <= 0xFF:
            raise CommandError(f"node address {self.node} out of range 0..255")
        if not 0 <= self.unit <= 0xFF:
            raise CommandError(f"unit address {self.unit} out of range 0..255")

    @classmethod
    def parse(cls, text: str) -> FinsAddress:
        """Parse ``"NET.NODE.UNIT"`` (decimal; unit optional), e.g. ``"1.10.0"``."""
        parts = text.split(".")
        if not 1 < len(parts) <= 3 or not all(p.strip().isdigit() for p in parts):
            raise CommandError(f"FINS address {text!r} is not NET.NODE[.UNIT]")
        values = [int(p) for p in parts] + [0] * (3 - len(parts))
        return cls(values[0], values[1], values[2])

    @classmethod
    def of(cls, value: object) -> FinsAddress:
        """``value`` itself, or parsed from ``"NET.NODE.UNIT"`` text (:meth:`parse`);
        :class:`CommandError` for anything else."""
        if isinstance(value, FinsAddress):
            return value
        if not isinstance(value, str):
            raise CommandError(
                f"a FINS address is a FinsAddress or 'NET.NODE.UNIT' text, got {value!r}"
            )
        return cls.parse(value)

    def __str__(self) -> str:
        return f"{self.network}.{self.node}.{self.unit}"


def _check_byte(name: str, value: int) -> None:
    if not 0 <= value <= 0xFF:
        raise CommandError(f"{name} {value} out of range 0..255")


@dataclass(frozen=True, slots=True)
class Header:
    """The 10-byte FINS header."""

    destination: FinsAddress
    source: FinsAddress
    sid: int = 0
    icf: int = ICF_GATEWAY
    rsv: int = 0
    gct: int = DEFAULT_GCT

    def __post_init__(self) -> None:
        _check_byte("SID", self.sid)
        _check_byte("ICF", self.icf)
        _check_byte("RSV", self.rsv)
        _check_byte("GCT", self.gct)

    @property
    def is_response(self) -> bool:
        return bool(self.icf & ICF_RESPONSE)

    @property
    def response_required(self) -> bool:
        return not self.icf & ICF_NO_RESPONSE

    def encode(self) -> bytes:
        d, s = self.destination, self.source
        return bytes(
            (
                self.icf,
                self.rsv,
                self.gct,
                d.network,
                d.node,
                d.unit,
                s.network,
                s.node,
                s.unit,
                self.sid,
            )
        )

    @classmethod
    def decode(cls, frame: bytes) -> Header:
        if len(frame) < HEADER_SIZE:
            raise FrameError(
                f"FINS frame of {len(frame)} bytes is shorter than its header", end_code=0x1002
            )
        b = frame
        if b[3] > 0x7F or b[6] > 0x7F:
            raise FrameError("network address above 127 in FINS header", end_code=0x1005)
        return cls(
            FinsAddress(b[3], b[4], b[5]),
            FinsAddress(b[6], b[7], b[8]),
            sid=b[9],
            icf=b[0],
            rsv=b[1],
            gct=b[2],
        )

    def reply_header(self) -> Header:
        """The header of the response to a command with this header."""
        return Header(
            self.source,
            self.destination,
            sid=self.sid,
            icf=(self.icf | ICF_RESPONSE) & ~ICF_NO_RESPONSE & 0xFF,
            rsv=self.rsv,
            gct=self.gct,
        )


@dataclass(frozen=True, slots=True)
class CommandFrame:
    """A whole FINS command: header, command code (MRC, SRC) and parameter bytes."""

    header: Header
    mrc: int
    src: int
    params: bytes = b""

    def __post_init__(self) -> None:
        _check_byte("MRC", self.mrc)
        _check_byte("SRC", self.src)
        if len(self.params) > MAX_PARAMETER_SIZE:
            raise CommandError(
                f"{len(self.params)} parameter bytes exceed the FINS frame "
                f"limit of {MAX_PARAMETER_SIZE}"
            )

    @property
    def command_code(self) -> int:
        return (self.mrc << 8) | self.src

    def encode(self) -> bytes:
        return self.header.encode() + bytes((self.mrc, self.src)) + self.params

    @classmethod
    def decode(cls, frame: bytes) -> CommandFrame:
        header = Header.decode(frame)
        if header.is_response:
            raise FrameError("frame has the response bit set in ICF")
        if len(frame) < HEADER_SIZE + COMMAND_CODE_SIZE:
            raise FrameError("FINS command frame has no command code", end_code=0x1002)
        if len(frame) > MAX_FRAME_SIZE:
            raise FrameError(
                f"FINS command frame of {len(frame)} bytes exceeds {MAX_FRAME_SIZE}",
                end_code=0x1001,
            )
        return cls(header, frame[10], frame[11], bytes(frame[12:]))


@dataclass(frozen=True, slots=True)
class ResponseFrame:
    """A whole FINS response.

    ``relay`` is ``(network, node)`` of the failing relay point when the end code has the
    relay-error flag (bit 15), else ``None``. ``data`` is what follows the end code (and the
    relay trailer).
    """

    header: Header
    mrc: int
    src: int
    end_code: EndCode
    data: bytes = b""
    relay: tuple[int, int] | None = field(default=None)

    @property
    def command_code(self) -> int:
        return (self.mrc << 8) | self.src

    def encode(self) -> bytes:
        raw = self.end_code.raw
        out = self.header.encode() + bytes((self.mrc, self.src, raw >> 8, raw & 0xFF))
        if self.end_code.relay_error:
            net, node = self.relay if self.relay is not None else (0, 0)
            out += bytes((net, node))
        return out + self.data

    @classmethod
    def decode(cls, frame: bytes) -> ResponseFrame:
        header = Header.decode(frame)
        if not header.is_response:
            raise FrameError("frame is not a response (ICF bit 6 clear)")
        if len(frame) < HEADER_SIZE + COMMAND_CODE_SIZE + END_CODE_SIZE:
            raise FrameError(f"FINS response of {len(frame)} bytes has no end code")
        if len(frame) > MAX_FRAME_SIZE + 2:
            raise FrameError(f"FINS response of {len(frame)} bytes exceeds {MAX_FRAME_SIZE}")
        end_code = EndCode.from_bytes(frame[12], frame[13])
        if end_code.relay_error:
            if len(frame) < 16:
                raise FrameError("relay error response lacks its network/node trailer")
            return cls(
                header, frame[10], frame[11], end_code, bytes(frame[16:]), (frame[14], frame[15])
            )
        return cls(header, frame[10], frame[11], end_code, bytes(frame[14:]))

    @classmethod
    def reply_to(
        cls,
        command: CommandFrame,
        end_code: EndCode | int = 0,
        data: bytes = b"",
        relay: tuple[int, int] | None = None,
    ) -> ResponseFrame:
        """Build the response to ``command``: addresses swapped, SID and code echoed."""
        if isinstance(end_code, int):
            end_code = EndCode(end_code)
        return cls(command.header.reply_header(), command.mrc, command.src, end_code, data, relay)


def build_command(
    destination: FinsAddress,
    source: FinsAddress,
    sid: int,
    mrc: int,
    src: int,
    params: bytes = b"",
    *,
    gct: int = DEFAULT_GCT,
    response_required: bool = True,
) -> bytes:
    """Encode a command frame in one step (the hot path of the client)."""
    return CommandFrame(
        Header(
            destination,
            source,
            sid=sid,
            icf=ICF_GATEWAY if response_required else ICF_GATEWAY | ICF_NO_RESPONSE,
            gct=gct,
        ),
        mrc,
        src,
        params,
    ).encode()
