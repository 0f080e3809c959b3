"""Every operation of manual section 5, one module per command family.

``ALL_OPERATIONS`` lists the 47 operations (45 command codes; 09 20 carries three).
``decode_request`` finds the operation of a received command (server side).
"""

from __future__ import annotations

from typing import Any

from ..errors import DecodeError
from . import (
    access,
    clock,
    debug,
    errorlog,
    file,
    gateway,
    machine,
    memory,
    message,
    mode,
    parameter,
    program,
    status,
)
from ._base import Request, encode_result, expect_no_data

ALL_OPERATIONS: tuple[type[Request[Any]], ...] = (
    *memory.OPERATIONS,
    *parameter.OPERATIONS,
    *program.OPERATIONS,
    *mode.OPERATIONS,
    *machine.OPERATIONS,
    *status.OPERATIONS,
    *clock.OPERATIONS,
    *message.OPERATIONS,
    *access.OPERATIONS,
    *errorlog.OPERATIONS,
    *file.OPERATIONS,
    *debug.OPERATIONS,
    *gateway.OPERATIONS,
)

_BY_CODE: dict[int, tuple[type[Request[Any]], ...]] = {}
for _op in ALL_OPERATIONS:
    _BY_CODE[_op.command_code()] = (*_BY_CODE.get(_op.command_code(), ()), _op)

#: Every command code of manual 5-1-1 that has at least one operation.
COMMAND_CODES: frozenset[int] = frozenset(_BY_CODE)


def operation_for(mrc: int, src: int, params: bytes) -> type[Request[Any]]:
    """The operation a command belongs to; :class:`DecodeError` (0401) if unknown."""
    candidates = _BY_CODE.get((mrc << 8) | src)
    if not candidates:
        raise DecodeError(f"undefined command code {mrc:02X}{src:02X}", end_code=0x0401)
    for op in candidates:
        if op.matches(params):
            return op
    raise DecodeError(f"parameters match no operation of {mrc:02X}{src:02X}", end_code=0x1104)


def decode_request(mrc: int, src: int, params: bytes) -> Request[Any]:
    """Decode a received command's parameters into its typed request."""
    return operation_for(mrc, src, params).decode(params)


__all__ = [
    "ALL_OPERATIONS",
    "COMMAND_CODES",
    "Request",
    "decode_request",
    "encode_result",
    "expect_no_data",
    "operation_for",
]
