"""The session's lifecycles, named: the link's and a request's.

:class:`LinkState` has one place where it changes,
:meth:`Link.set_state <aiofins.session.link.Link.set_state>`, which checks each move against
:data:`LINK_TRANSITIONS`, logs it and emits :class:`~aiofins.hooks.ConnectionStateChanged`.
:class:`RequestState` names the stages a request goes through; :attr:`Pending.state` reads it
off the request in flight.
"""

from __future__ import annotations

import enum


class LinkState(enum.Enum):
    """Where the session's link (its transport) stands."""

    #: Not connected: before the first connection, or after the link was lost. The next call
    #: starts a connection attempt.
    CLOSED = "closed"
    #: A connection attempt runs in the background; calls wait for it, each at most its own
    #: deadline.
    CONNECTING = "connecting"
    #: Frames can be sent.
    OPEN = "open"
    #: The last connection attempt failed: calls fail at once until the (jittered) backoff
    #: ends, then the next call starts another attempt.
    BACKOFF = "backoff"
    #: Closed for good by ``aclose()``; every call fails with ``ConnectionLost``.
    SHUT = "shut"


#: The moves the link may make; anything else is a bug (``AssertionError``).
LINK_TRANSITIONS: dict[LinkState, frozenset[LinkState]] = {
    LinkState.CLOSED: frozenset({LinkState.CONNECTING, LinkState.SHUT}),
    LinkState.CONNECTING: frozenset(
        {LinkState.OPEN, LinkState.BACKOFF, LinkState.CLOSED, LinkState.SHUT}
    ),
    LinkState.OPEN: frozenset({LinkState.CLOSED, LinkState.SHUT}),
    LinkState.BACKOFF: frozenset({LinkState.CONNECTING, LinkState.SHUT}),
    LinkState.SHUT: frozenset(),
}


class RequestState(enum.Enum):
    """The stages of one request."""

    #: Waiting for an in-flight slot of its destination, a free SID or the link.
    QUEUED = "queued"
    #: On the wire once, awaiting its reply (registered under its SID).
    SENT = "sent"
    #: Sent again with the same frame and SID after no reply within the retransmission
    #: timeout; whichever reply comes first answers it.
    RETRANSMITTED = "retransmitted"
    #: A reply answered it (whatever the end code).
    ANSWERED = "answered"
    #: Given up on: its call's deadline passed, it was cancelled, or the link failed. Its
    #: SID is quarantined until its late reply comes or the quarantine ends.
    ABANDONED = "abandoned"
    #: Answered, and its SID lingers: not reused while a duplicate of its reply (the network's,
    #: or the reply to a retransmission) could still arrive.
    LINGERING = "lingering"
