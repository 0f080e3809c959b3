"""What the session's errors say when a call gets no answer or no SID (the words in one
place, out of the hot path's module)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..protocol.errors import FinsTimeout
from ..protocol.header import FinsAddress
from .slots import DestState, SlotTimeout

if TYPE_CHECKING:
    from .core import Session


def no_response(
    session: Session, dest: FinsAddress, mrc: int, src: int, timeout: float, attempts: int = 1
) -> FinsTimeout:
    """The error of a call to ``dest`` (command ``mrc src``) that got no reply within its
    ``timeout`` after ``attempts`` transmissions: what to check."""
    s = session.source
    tries = "1 attempt" if attempts == 1 else f"{attempts} attempts"
    return FinsTimeout(
        f"no response to command {mrc:02X}{src:02X} from {dest} in {tries} within "
        f"{timeout} s via {session.transport.description}. "
        f"{session.transport.silence_advice(dest, s)}"
    )


def no_free_sid(session: Session, state: DestState, timeout: float) -> SlotTimeout:
    """The error of a call that found no free SID of ``state``'s destination within
    ``timeout``: why SIDs are taken."""
    sids = session.sids
    return SlotTimeout(
        f"no free SID for {state.address} within {timeout} s: all 256 are in flight, "
        f"quarantined or lingering ({len(sids.quarantine)} SIDs of this session wait for late "
        f"replies to requests that timed out or were cancelled, {len(sids.lingering)} linger "
        "after their reply in case a duplicate follows; a SID is free again when its late "
        "reply arrives or its quarantine or linger ends)"
    )
