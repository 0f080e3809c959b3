"""Each PLC's online/offline state, from the outcome of its groups' scans.

A PLC is online while the last scan of at least one of its groups succeeded, offline once the
last scan of every one of them failed. The gateway publishes the state on the PLC's status
topic when it changes (once per transition, not per scan).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum


class PlcState(Enum):
    """A PLC's lifecycle as the gateway sees it (transitions in :meth:`PlcStatus.observe`)."""

    #: No scan of the PLC has finished yet.
    UNKNOWN = "unknown"
    #: The last scan of at least one of its groups succeeded.
    ONLINE = "online"
    #: The last scan of every one of its groups failed.
    OFFLINE = "offline"


@dataclass(eq=False)
class PlcStatus:
    """One PLC's state, the last outcome of each of its groups and the transitions seen."""

    name: str
    state: PlcState = PlcState.UNKNOWN
    transitions: int = 0
    #: Why the PLC went offline (the last failed scan's error).
    reason: str | None = None
    _last_ok: dict[str, bool] = field(default_factory=dict)

    def observe(self, group: str, error: str | None) -> PlcState | None:
        """Record a scan's outcome; the new state if the PLC's state changed, else None."""
        ok = error is None
        if self._last_ok.get(group) is ok and self.state is not PlcState.UNKNOWN:
            return None
        self._last_ok[group] = ok
        new = PlcState.ONLINE if any(self._last_ok.values()) else PlcState.OFFLINE
        if new is self.state:
            return None
        self.state = new
        self.reason = error if new is PlcState.OFFLINE else None
        self.transitions += 1
        return new
