"""Serial gateway: 2803 CompoWay/F, 2804 Modbus-RTU, 2805 Modbus-ASCII (5-3-46 to 5-3-48).

The serial device behind the port is ``plc.gateway`` (a callable taking the command code
and the encapsulated command, returning what follows the FINS end code); the codec's
response type wraps it. :func:`default_gateway` is a stub device: a Modbus slave whose
registers and coils are all zero and which echoes writes, and a CompoWay/F node that answers
every command with response code ``0000``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...protocol.commands.gateway import (
    CompowayFResponse,
    ConvertToCompowayFCommand,
    ConvertToModbusAsciiCommand,
    ConvertToModbusRtuCommand,
    GatewayResponse,
    ModbusAsciiResponse,
    ModbusRtuResponse,
)
from ..codes import Operation, by_command_code
from ._call import Call, Handler, request_of

if TYPE_CHECKING:
    from ..plc import VirtualPLC

MODBUS_ILLEGAL_FUNCTION = 0x01


def _modbus_reply(pdu: bytes) -> bytes:
    """A zero-filled Modbus slave: slave address + function code + data → its response."""
    slave, fc, data = pdu[0], pdu[1], pdu[2:]
    if fc in (1, 2, 3, 4) and len(data) >= 4:
        quantity = int.from_bytes(data[2:4], "big")
        size = (quantity + 7) // 8 if fc in (1, 2) else 2 * quantity
        return bytes((slave, fc, size & 0xFF)) + bytes(size & 0xFF)
    if fc in (5, 6):
        return pdu  # a single write is echoed
    if fc in (15, 16) and len(data) >= 4:
        return bytes((slave, fc)) + data[:4]  # address and quantity written
    return bytes((slave, fc | 0x80, MODBUS_ILLEGAL_FUNCTION))


def default_gateway(command_code: int, params: bytes) -> bytes:
    """The stub serial device behind the gateway (see the module docstring)."""
    if command_code == ConvertToCompowayFCommand.command_code():
        # node (2) + sub-address (2) + end code "00" + command MRC/SRC (4) + response "0000"
        return params[0:4] + b"00" + params[5:9] + b"0000"
    if command_code == ConvertToModbusRtuCommand.command_code():
        return _modbus_reply(params)
    try:  # Modbus-ASCII: the same exchange, each byte as two hex characters
        pdu = bytes.fromhex(params.decode("ascii"))
    except ValueError:
        return params
    return _modbus_reply(pdu).hex().upper().encode("ascii") if len(pdu) >= 2 else params


#: Each gateway operation and the response type wrapping what the serial device answered.
_RESPONSE_TYPES: dict[Operation, type[GatewayResponse]] = {
    ConvertToCompowayFCommand: CompowayFResponse,
    ConvertToModbusRtuCommand: ModbusRtuResponse,
    ConvertToModbusAsciiCommand: ModbusAsciiResponse,
}
_TYPES: dict[int, tuple[Operation, type[GatewayResponse]]] = by_command_code(
    {op: (op, response) for op, response in _RESPONSE_TYPES.items()}
)


def convert(plc: VirtualPLC, call: Call) -> bytes:
    request_type, response_type = _TYPES[call.command_code]
    request_of(call, request_type)
    return response_type(plc.gateway(call.command_code, call.params)).encode()


HANDLERS: dict[int, Handler] = by_command_code(dict.fromkeys(_RESPONSE_TYPES, convert))
