"""Simulator tables written with the protocol's operation classes, looked up by command code.

A command code is spelled once, in the protocol (``MRC``/``SRC`` of each operation); the
virtual PLC's tables name the operation and take the code from it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeAlias, TypeVar

from ..protocol.commands import Request

#: An operation class of the protocol, e.g. ``MemoryAreaRead``.
Operation: TypeAlias = type[Request[Any]]

V = TypeVar("V")


def by_command_code(table: Mapping[Operation, V]) -> dict[int, V]:
    """``table`` keyed by each operation's command code, in the same order.

    Operations sharing a code (09 20) must share the value: one command code, one entry.
    """
    out: dict[int, V] = {}
    for op, value in table.items():
        code = op.command_code()
        if code in out and out[code] is not value:
            raise ValueError(f"{op.NAME}: command code {code:04X} already has another entry")
        out[code] = value
    return out
