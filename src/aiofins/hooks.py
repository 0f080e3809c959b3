"""Event hooks: small typed callbacks for what happens to requests, links and scans.

A leaf module (it imports :mod:`aiofins.protocol` only), so every layer can emit these events
and every integration (logging, metrics, tracing) can consume them without importing the
session, the pool or the poller. Events are frozen, slotted dataclasses named in the
domain's words; :class:`EventHooks` holds one list of callbacks per event type.

Cheap when unused: an emitter keeps ``None`` instead of an :class:`EventHooks` without
callbacks (see :meth:`EventHooks.or_none`) and checks that once per event. A callback that
raises is caught, logged (``aiofins.hooks``, with the traceback) and counted in
:attr:`EventHooks.errors`; it never breaks a request, a link or a scan.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from .protocol.header import FinsAddress

__all__ = [
    "ConnectionStateChanged",
    "EventHooks",
    "RequestRetried",
    "RequestSent",
    "RequestTimedOut",
    "ResponseReceived",
    "ScanDone",
    "SidSpaceChanged",
]

logger = logging.getLogger("aiofins.hooks")


@dataclass(frozen=True, slots=True)
class RequestSent:
    """A command frame went out (its first transmission)."""

    #: Where the frames go, e.g. ``udp://10.0.0.5:9600``.
    endpoint: str
    #: The destination FINS address.
    dest: FinsAddress
    #: The service ID the reply must carry.
    sid: int
    #: MRC << 8 | SRC, e.g. ``0x0101`` for MEMORY AREA READ.
    command_code: int


@dataclass(frozen=True, slots=True)
class ResponseReceived:
    """A reply answered a request (whatever its end code)."""

    endpoint: str
    dest: FinsAddress
    sid: int
    command_code: int
    #: The reply's end code (main << 8 | sub, flags included).
    end_code: int
    #: Seconds from the first transmission to the reply.
    elapsed: float
    #: Transmissions made before the reply came (1 = answered at the first).
    attempts: int


@dataclass(frozen=True, slots=True)
class RequestRetried:
    """A request was sent again: the same frame and SID after no reply within the
    retransmission timeout."""

    endpoint: str
    dest: FinsAddress
    sid: int
    command_code: int
    #: Which transmission this is (2 = the first retransmission).
    attempt: int
    #: Seconds since the first transmission.
    elapsed: float


@dataclass(frozen=True, slots=True)
class RequestTimedOut:
    """A request got no reply within its call's deadline, after every transmission."""

    endpoint: str
    dest: FinsAddress
    sid: int
    command_code: int
    #: Transmissions made.
    attempts: int
    #: Seconds from the first transmission to giving up.
    elapsed: float


@dataclass(frozen=True, slots=True)
class ConnectionStateChanged:
    """A link (session) moved from one state to another (names of ``LinkState`` members)."""

    endpoint: str
    old: str
    new: str


@dataclass(frozen=True, slots=True)
class SidSpaceChanged:
    """One of a session's extra SID spaces (another UDP socket or FINS/TCP connection,
    opened when the SIDs of the spaces before it were all taken) moved from one state to
    another (names of ``SpaceState`` members)."""

    endpoint: str
    #: The space's number (1 for the first extra space; the session's own is 0).
    space: int
    #: The state it left (``None``: just made, opening).
    old: str | None
    new: str
    #: Its source node (SA1), once known.
    node: int | None


@dataclass(frozen=True, slots=True)
class ScanDone:
    """A poller group finished one scan."""

    #: The group's name.
    group: str
    #: The scan's number in its group (1 = the first).
    scan: int
    #: Seconds the scan took.
    duration: float
    #: Scans skipped after this one because it ran late (or the consumer was slow).
    missed: int
    #: Why the scan failed (its tags then keep their last values as stale), else ``None``.
    error: str | None = None


#: Command families by MRC (FINS manual section 5), as metrics and spans name them.
FAMILIES = {
    0x01: "memory",
    0x02: "parameter",
    0x03: "program",
    0x04: "mode",
    0x05: "machine",
    0x06: "status",
    0x07: "clock",
    0x09: "message",
    0x0C: "access",
    0x21: "errorlog",
    0x22: "file",
    0x23: "debug",
    0x28: "gateway",
}
#: The family of a command code no family above has.
OTHER_FAMILY = "other"


def command_family(command_code: int) -> str:
    """The family of a command code, named after its MRC (``0x0101`` -> ``memory``)."""
    return FAMILIES.get(command_code >> 8, OTHER_FAMILY)


E = TypeVar("E")


@dataclass(slots=True, eq=False)
class EventHooks:
    """Callbacks per event type; add with ``hooks.request_sent.append(fn)`` or at
    construction (``EventHooks(response_received=[fn])``).

    A callback takes the event and returns nothing (a return value is ignored). It runs
    synchronously where the event happens (in the receive path for a reply): keep it short,
    hand slow work to a queue.
    """

    request_sent: list[Callable[[RequestSent], object]] = field(default_factory=list)
    response_received: list[Callable[[ResponseReceived], object]] = field(default_factory=list)
    request_retried: list[Callable[[RequestRetried], object]] = field(default_factory=list)
    request_timed_out: list[Callable[[RequestTimedOut], object]] = field(default_factory=list)
    connection_state_changed: list[Callable[[ConnectionStateChanged], object]] = field(
        default_factory=list
    )
    sid_space_changed: list[Callable[[SidSpaceChanged], object]] = field(default_factory=list)
    scan_done: list[Callable[[ScanDone], object]] = field(default_factory=list)
    #: Callbacks that raised (each caught, logged and counted here).
    errors: int = 0

    def __bool__(self) -> bool:
        """Whether any callback is registered."""
        return bool(
            self.request_sent
            or self.response_received
            or self.request_retried
            or self.request_timed_out
            or self.connection_state_changed
            or self.sid_space_changed
            or self.scan_done
        )

    @classmethod
    def combine(cls, *hooks: EventHooks) -> EventHooks:
        """One set of hooks calling those of each of ``hooks`` in turn (e.g. metrics and
        tracing for one pool)."""
        combined = cls()
        for name in _EVENT_LISTS:
            callbacks: list[Callable[[Any], object]] = getattr(combined, name)
            for h in hooks:
                callbacks.extend(getattr(h, name))
        return combined

    def or_none(self) -> EventHooks | None:
        """``self`` if any callback is registered, else ``None`` (what emitters keep)."""
        return self if self else None

    def emit(self, callbacks: list[Callable[[E], object]], event: E) -> None:
        """Call each of ``callbacks`` with ``event``; a raising callback is logged, counted
        and skipped, never raised."""
        for callback in callbacks:
            try:
                callback(event)
            except Exception:
                self.errors += 1
                logger.exception("event hook %r raised on %s", callback, type(event).__name__)


#: The callback lists of :class:`EventHooks`, one per event type.
_EVENT_LISTS = (
    "request_sent",
    "response_received",
    "request_retried",
    "request_timed_out",
    "connection_state_changed",
    "sid_space_changed",
    "scan_done",
)
