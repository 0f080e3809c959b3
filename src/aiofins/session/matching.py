"""Replies that do not carry the exact key of a request: wildcards, relay errors, strays."""

from __future__ import annotations

from .response import SessionStats
from .slots import Pending


def match_wildcard(pending: dict[int, Pending], key: int) -> Pending | None:
    """A request to network 0 (local) or node 0 may be answered with the real numbers."""
    for mask in (0x00FFFFFF, 0xFF00FFFF, 0x0000FFFF):
        p = pending.get(key & mask)
        if p is not None:
            return p
    return None


def match_relay_error(pending: dict[int, Pending], frame: bytes) -> Pending | None:
    """A relay error comes from the relay point, not from the destination we asked.

    Its address (``SNA SA1 SA2``) is the relay's, and its trailer names where forwarding
    failed, which may be any network on the route: nothing in it names the destination.
    So it is matched on SID and command code alone, and only when exactly one request in
    flight on this SID space fits; with several it answers none (it is counted as
    unmatched, and each request gets its own reply or times out). The session makes
    several impossible: while it addresses several destinations a SID is in flight to one
    at a time, and one that may still get a late relay error is given to no request to
    another destination (see :meth:`SidSpace.relay_taken
    <aiofins.session.sids.SidSpace.relay_taken>`).
    """
    sid, mrc, src = frame[9], frame[10], frame[11]
    fits = [p for k, p in pending.items() if k & 0xFF == sid and p.mrc == mrc and p.src == src]
    return fits[0] if len(fits) == 1 else None


#: A SID whose late reply has come stays quarantined this much longer (or the link's linger,
#: if longer; no more and no less): room for a duplicate of that reply, which must not reach
#: the SID's next request either.
LATE_REPLY_GRACE = 0.5
#: A SID answered by a relay error lingers at least this long (or the link's linger, if
#: longer), for every destination while the session addresses several: a copy of the relay
#: error, matched by SID and command code alone (and under the key of the relay's own CPU),
#: would fit any request that took the SID, whether or not the link has shown duplicates.
RELAY_LINGER = LATE_REPLY_GRACE


def count_unmatched(
    stats: SessionStats,
    quarantine: dict[int, float],
    answers: dict[int, bytes],
    key: int,
    frame: bytes,
    now: float,
    relay_error: bool = False,
    grace: float = LATE_REPLY_GRACE,
) -> tuple[str, int]:
    """Count a reply ``frame`` no request waits for: late (timed out), duplicate, or
    unsolicited.

    A late reply also ends its SID's quarantine ``grace`` seconds (at least
    :data:`LATE_REPLY_GRACE`) from ``now``, the session's time: the reply the quarantine
    waited for has come, and a copy of it may follow (a quarantine about to end is
    lengthened to that). A relay error (``relay_error``: its key names the relay point) is
    late for any SID quarantined under its SID number. A duplicate is a copy of the reply
    its SID was last answered with (``answers``: key -> that reply; for a relay error,
    ``key`` is that of the request its SID number last answered, see
    :meth:`SidSpace.unmatched <aiofins.session.sids.SidSpace.unmatched>`). Returns which
    (``"late"``, ``"duplicate"`` or ``"unsolicited"``) and the key it was counted under
    (for a duplicate: the key of the reply it copies).
    """
    end = now + grace
    if relay_error:
        sid = key & 0xFF
        mine = [k for k in quarantine if k & 0xFF == sid]
        if mine:
            stats.late_replies += 1
            for k in mine:
                quarantine[k] = end
            return "late", mine[0]
    keys = (key, key & 0x00FFFFFF, key & 0xFF00FFFF, key & 0x0000FFFF)
    for k in keys:
        if k in quarantine:
            stats.late_replies += 1
            quarantine[k] = end
            return "late", k
    for k in keys:
        if answers.get(k) == frame:
            stats.duplicates += 1
            return "duplicate", k
    stats.unsolicited += 1
    return "unsolicited", key
