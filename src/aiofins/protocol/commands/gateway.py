"""Serial Gateway commands 2803/2804/2805 (manual 5-3-46..5-3-48).

The FINS command carries a CompoWay/F, Modbus-RTU or Modbus-ASCII command; the serial
port (Serial Communications Unit/Board, CP option board) strips the FINS part, adds the
serial framing (STX/ETX/BCC, CRC, ``:``/LRC/CRLF) and sends it. The port is chosen by the
destination **unit address** (DA2) of the FINS header: see :func:`serial_port_unit_address`.
The payloads stay raw bytes; the requests validate the manual's limits and offer parsed
views (``node``, ``slave_address``, ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

from ..decoding import as_decode_error
from ..errors import CommandError, DecodeError
from ..header import MAX_PARAMETER_SIZE
from ._base import Request

#: Unit addresses of the built-in serial ports of CP1H/CP1L CPU Units (option boards).
CP_SERIAL_PORT_1 = 0xFD
CP_SERIAL_PORT_2 = 0xFC
#: Modbus-RTU: slave address + PDU (at most 253) — a 256-byte ADU less the 2-byte CRC.
MAX_MODBUS_RTU_PAYLOAD = 254
#: Modbus-ASCII: the same 254 bytes as hex characters (the ``:``, LRC and CRLF are added).
MAX_MODBUS_ASCII_PAYLOAD = 2 * MAX_MODBUS_RTU_PAYLOAD
_HEX_UPPER = frozenset(b"0123456789ABCDEF")
_HEX_ANY = _HEX_UPPER | frozenset(b"abcdef")


def serial_port_unit_address(port: int, unit_number: int | None = None) -> int:
    """DA2 of serial port 1 or 2: of Serial Communications Unit ``unit_number`` (0..15),
    ``80 + 4 * unit + port - 1`` hex, or of the Serial Communications Board (``None``),
    E4/E5 hex. CP1H/CP1L built-in ports: :data:`CP_SERIAL_PORT_1`/:data:`CP_SERIAL_PORT_2`.
    """
    if port not in (1, 2):
        raise CommandError(f"serial port {port!r} must be 1 or 2")
    if unit_number is None:
        return 0xE4 + port - 1
    if isinstance(unit_number, bool) or not 0 <= unit_number <= 15:
        raise CommandError(f"unit number {unit_number!r} out of range 0..15")
    return 0x80 + 4 * unit_number + port - 1


def _printable(raw: bytes) -> bool:
    return all(0x20 <= b <= 0x7E for b in raw)


def _check_size(what: str, payload: bytes, low: int, high: int) -> bytes:
    payload = bytes(payload)
    if not low <= len(payload) <= high:
        raise CommandError(f"{what} is {len(payload)} bytes, must be {low}..{high}")
    return payload


@dataclass(frozen=True, slots=True)
class GatewayResponse:
    """Response data of a serial gateway command: the serial device's reply, raw."""

    payload: bytes

    MINIMUM: ClassVar[int] = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "payload", bytes(self.payload))

    def encode(self) -> bytes:
        return self.payload

    @classmethod
    def _decode_checked(cls, data: bytes, what: str) -> Any:
        if len(data) < cls.MINIMUM:
            raise DecodeError(f"{what} response: {len(data)} bytes, at least {cls.MINIMUM}")
        try:
            return cls(data)
        except CommandError as exc:
            raise DecodeError(f"{what} response: {exc}") from exc


class _ModbusFields:
    """Slave address, function code and data of a Modbus payload: binary (RTU) or, with
    ``_ASCII``, as pairs of hex characters."""

    __slots__ = ()

    _ASCII: ClassVar[bool] = False
    payload: bytes

    def _byte(self, index: int) -> int:
        if self._ASCII:
            return int(self.payload[2 * index : 2 * index + 2], 16)
        return self.payload[index]

    @property
    def slave_address(self) -> int:
        return self._byte(0)

    @property
    def function_code(self) -> int:
        return self._byte(1)

    @property
    def data(self) -> bytes:
        """The data after the function code (Modbus-ASCII: converted from hex to bytes)."""
        if self._ASCII:
            return bytes.fromhex(self.payload[4:].decode("ascii"))
        return self.payload[2:]


@dataclass(frozen=True, slots=True)
class CompowayFResponse(GatewayResponse):
    """2803 response: node (2), sub-address (2), end code (2, ASCII) then, for end code
    ``"00"``, the CompoWay/F command code (4), response code (4) and text."""

    MINIMUM: ClassVar[int] = 6

    @property
    def node(self) -> str:
        return self.payload[0:2].decode("latin-1")

    @property
    def subaddress(self) -> str:
        return self.payload[2:4].decode("latin-1")

    @property
    def end_code(self) -> str:
        """The CompoWay/F frame end code; ``"00"`` is normal."""
        return self.payload[4:6].decode("latin-1")

    @property
    def compoway_command(self) -> str | None:
        return self.payload[6:10].decode("latin-1") if len(self.payload) >= 10 else None

    @property
    def response_code(self) -> str | None:
        """The service result (``"0000"`` normal); ``None`` when the frame carries none."""
        return self.payload[10:14].decode("latin-1") if len(self.payload) >= 14 else None

    @property
    def text(self) -> bytes:
        return self.payload[14:]


@dataclass(frozen=True, slots=True)
class _ModbusResponse(_ModbusFields, GatewayResponse):
    """The part the 2804/2805 responses share."""

    @property
    def is_exception(self) -> bool:
        """Function code with bit 7 set: ``data[0]`` is the Modbus exception code."""
        return bool(self.function_code & 0x80)


@dataclass(frozen=True, slots=True)
class ModbusRtuResponse(_ModbusResponse):
    """2804 response: slave address, function code, data (binary, CRC removed)."""

    MINIMUM: ClassVar[int] = 2


@dataclass(frozen=True, slots=True)
class ModbusAsciiResponse(_ModbusResponse):
    """2805 response: slave address, function code and data as hex characters."""

    MINIMUM: ClassVar[int] = 4
    _ASCII: ClassVar[bool] = True

    def __post_init__(self) -> None:
        GatewayResponse.__post_init__(self)
        if len(self.payload) % 2 or not set(self.payload) <= _HEX_ANY:
            raise CommandError(f"Modbus-ASCII reply {self.payload!r} is not pairs of hex digits")


R = TypeVar("R", bound=GatewayResponse)
G = TypeVar("G", bound="_GatewayCommand[Any]")
M = TypeVar("M", bound="_ModbusCommand[Any]")


@dataclass(frozen=True)
class _GatewayCommand(Request[R]):
    """The part 2803/2804/2805 share: the parameters are the raw ``payload``."""

    #: Shortest payload; shorter parameters are answered with end code 1002.
    _MINIMUM: ClassVar[int]
    _RESPONSE: ClassVar[type[GatewayResponse]]

    payload: bytes

    def encode(self) -> bytes:
        return self.payload

    @classmethod
    def decode(cls: type[G], params: bytes) -> G:
        if len(params) < cls._MINIMUM:
            raise DecodeError(
                f"{cls.NAME}: {len(params)} parameter bytes, at least {cls._MINIMUM}",
                end_code=0x1002,
            )
        with as_decode_error(cls.NAME):
            return cls(params)

    def decode_response(self, data: bytes) -> R:
        result: R = self._RESPONSE._decode_checked(data, self.NAME)
        return result


# --------------------------------------------------------------------------- 2803


@dataclass(frozen=True)
class ConvertToCompowayFCommand(_GatewayCommand[CompowayFResponse]):
    """2803: send a CompoWay/F command through a serial port (send to its unit address).

    ``payload`` (ASCII): node number (2: ``"00"``..``"99"`` or ``"XX"`` broadcast),
    sub-address (2, usually ``"00"``), SID (1, usually ``"0"``), command code (4 hex
    characters, MRC + SRC) and text. :meth:`build` assembles one.
    """

    MRC: ClassVar[int] = 0x28
    SRC: ClassVar[int] = 0x03
    NAME: ClassVar[str] = "CONVERT TO COMPOWAY/F COMMAND"
    METHOD: ClassVar[str] = "convert_to_compoway_f_command"
    _MINIMUM: ClassVar[int] = 9
    _RESPONSE: ClassVar[type[GatewayResponse]] = CompowayFResponse

    def __post_init__(self) -> None:
        p = _check_size("CompoWay/F command", self.payload, self._MINIMUM, MAX_PARAMETER_SIZE)
        object.__setattr__(self, "payload", p)
        if not _printable(p):
            raise CommandError(f"CompoWay/F command {p!r} must be printable ASCII")
        if not (p[0:2].isdigit() or p[0:2] == b"XX"):
            raise CommandError(f"CompoWay/F node number {p[0:2]!r} must be 00..99 or XX")
        if not set(p[5:9]) <= _HEX_UPPER:
            raise CommandError(f"CompoWay/F command code {p[5:9]!r} must be 4 hex digits")

    @classmethod
    def build(
        cls,
        node: int | str,
        command: str,
        text: bytes | str = b"",
        *,
        subaddress: str = "00",
        sid: str = "0",
    ) -> ConvertToCompowayFCommand:
        """``build(1, "0101", "C00000000001")`` → node ``01``, read variable area."""
        if isinstance(node, int):
            if isinstance(node, bool) or not 0 <= node <= 99:
                raise CommandError(f"CompoWay/F node number {node!r} out of range 0..99")
            node = f"{node:02d}"
        if len(subaddress) != 2 or len(sid) != 1 or len(command) != 4:
            raise CommandError("sub-address is 2 characters, SID 1, command code 4")
        raw_text = text.encode("ascii", "replace") if isinstance(text, str) else text
        head = f"{node}{subaddress}{sid}{command}".encode("ascii", "replace")
        return cls(head + bytes(raw_text))

    @property
    def node(self) -> str:
        return self.payload[0:2].decode("ascii")

    @property
    def subaddress(self) -> str:
        return self.payload[2:4].decode("ascii")

    @property
    def sid(self) -> str:
        return self.payload[4:5].decode("ascii")

    @property
    def compoway_command(self) -> str:
        return self.payload[5:9].decode("ascii")

    @property
    def text(self) -> bytes:
        return self.payload[9:]


# --------------------------------------------------------------------------- 2804, 2805


@dataclass(frozen=True)
class _ModbusCommand(_ModbusFields, _GatewayCommand[R]):
    """The part 2804/2805 share: ``payload`` is slave address, function code, data."""

    @classmethod
    def build(cls: type[M], slave_address: int, function_code: int, data: bytes = b"") -> M:
        """``build(1, 3, bytes.fromhex("00000002"))``: read 2 holding registers of slave 1
        (Modbus-ASCII: payload ``b"010300000002"``)."""
        if not 0 <= slave_address <= 0xFF or not 0 <= function_code <= 0xFF:
            raise CommandError(
                f"slave address {slave_address} / function code {function_code} not bytes"
            )
        raw = bytes((slave_address, function_code)) + bytes(data)
        return cls(raw.hex().upper().encode("ascii") if cls._ASCII else raw)


@dataclass(frozen=True)
class ConvertToModbusRtuCommand(_ModbusCommand[ModbusRtuResponse]):
    """2804: send a Modbus-RTU command through a serial port (the port adds the CRC).

    ``payload``: slave address (01..F7), function code (01..FF), data; :meth:`build`.
    """

    MRC: ClassVar[int] = 0x28
    SRC: ClassVar[int] = 0x04
    NAME: ClassVar[str] = "CONVERT TO MODBUS-RTU COMMAND"
    METHOD: ClassVar[str] = "convert_to_modbus_rtu_command"
    _MINIMUM: ClassVar[int] = 2
    _RESPONSE: ClassVar[type[GatewayResponse]] = ModbusRtuResponse

    def __post_init__(self) -> None:
        p = _check_size("Modbus-RTU command", self.payload, self._MINIMUM, MAX_MODBUS_RTU_PAYLOAD)
        object.__setattr__(self, "payload", p)
        if not 1 <= p[0] <= 0xF7:
            raise CommandError(f"Modbus slave address {p[0]} out of range 1..247")
        if p[1] == 0:
            raise CommandError("Modbus function code 0 out of range 1..255")


@dataclass(frozen=True)
class ConvertToModbusAsciiCommand(_ModbusCommand[ModbusAsciiResponse]):
    """2805: send a Modbus-ASCII command through a serial port (it adds ``:``, LRC, CRLF).

    ``payload``: uppercase hex characters: slave address (``"01"``..``"F7"``), function
    code (``"01"``..``"FF"``), data; :meth:`build` converts binary data.
    """

    MRC: ClassVar[int] = 0x28
    SRC: ClassVar[int] = 0x05
    NAME: ClassVar[str] = "CONVERT TO MODBUS-ASCII COMMAND"
    METHOD: ClassVar[str] = "convert_to_modbus_ascii_command"
    _ASCII: ClassVar[bool] = True
    _MINIMUM: ClassVar[int] = 4
    _RESPONSE: ClassVar[type[GatewayResponse]] = ModbusAsciiResponse

    def __post_init__(self) -> None:
        p = _check_size(
            "Modbus-ASCII command", self.payload, self._MINIMUM, MAX_MODBUS_ASCII_PAYLOAD
        )
        object.__setattr__(self, "payload", p)
        if len(p) % 2 or not set(p) <= _HEX_UPPER:
            raise CommandError(f"Modbus-ASCII command {p!r} must be pairs of hex digits 0-9A-F")
        if not 1 <= int(p[0:2], 16) <= 0xF7:
            raise CommandError(f"Modbus slave address {p[0:2]!r} out of range 01..F7")
        if p[2:4] == b"00":
            raise CommandError("Modbus function code 00 out of range 01..FF")


OPERATIONS: tuple[type[Request[Any]], ...] = (
    ConvertToCompowayFCommand,
    ConvertToModbusRtuCommand,
    ConvertToModbusAsciiCommand,
)
