"""What every handler receives, and the pluggable serial-gateway answerer."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from ...protocol.header import FinsAddress
from ..state import UNDEFINED_COMMAND, CommandFailed

if TYPE_CHECKING:
    from ..plc import VirtualPLC


@dataclass(frozen=True, slots=True)
class Call:
    """One command as a handler sees it."""

    command_code: int
    params: bytes
    source: FinsAddress
    #: The typed request the protocol codec decoded (``None`` when the handler decides).
    request: Any = None


Q = TypeVar("Q")


def request_of(call: Call, cls: type[Q]) -> Q:
    """The decoded request, which must be a ``cls``."""
    if not isinstance(call.request, cls):
        raise CommandFailed(UNDEFINED_COMMAND, message=f"no {cls.__name__} decoded")
    return call.request


Handler = Callable[["VirtualPLC", Call], bytes]

#: Answers a serial gateway command (2803/2804/2805): params in, response data out.
GatewayHandler = Callable[[int, bytes], bytes]
