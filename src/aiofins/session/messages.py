"""What the session's errors say when a call gets no answer or no SID (the words in one
place, out of the hot path's module)."""

from __future__ import annotations

from collections.abc import Sized
from typing import Protocol

from ..protocol.errors import FinsTimeout
from ..protocol.header import FinsAddress
from ..transport.base import Transport
from .slots import DestState, SlotTimeout


class TakenSids(Protocol):
    """What :func:`no_free_sid` says of a SID space (a :class:`~.sids.SidSpace`)."""

    @property
    def quarantine(self) -> Sized: ...

    @property
    def lingering(self) -> Sized: ...


def no_response(
    transport: Transport,
    source: FinsAddress,
    dest: FinsAddress,
    mrc: int,
    src: int,
    timeout: float,
    attempts: int = 1,
) -> FinsTimeout:
    """The error of a call from ``source`` to ``dest`` via ``transport`` (command ``mrc
    src``) that got no reply within its ``timeout`` after ``attempts`` transmissions: what
    to check."""
    tries = "1 attempt" if attempts == 1 else f"{attempts} attempts"
    return FinsTimeout(
        f"no response to command {mrc:02X}{src:02X} from {dest} in {tries} within "
        f"{timeout} s via {transport.description}. "
        f"{transport.silence_advice(dest, source)}"
    )


def no_free_sid(sids: TakenSids, state: DestState, timeout: float) -> SlotTimeout:
    """The error of a call that found no free SID of ``state``'s destination within
    ``timeout`` (``sids``: the session's own SID space): why SIDs are taken."""
    return SlotTimeout(
        f"no free SID for {state.address} within {timeout} s: all 256 are in flight, "
        f"quarantined or lingering ({len(sids.quarantine)} SIDs of this session wait for late "
        f"replies to requests that timed out or were cancelled, {len(sids.lingering)} linger "
        "after their reply in case a duplicate follows; a SID is free again when its late "
        "reply arrives or its quarantine or linger ends)"
    )
