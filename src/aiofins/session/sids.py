"""One SID space: the SIDs of one socket or connection, and the requests in flight on it.

A reply carries back the 32-bit key ``SNA SA1 SA2 SID`` of its request (the destination's
network, node and unit, and the SID), so the requests in flight of one transport are a dict
keyed by it. A SID may carry a new request only when no reply to its previous use can still
arrive:

- **in flight** (in :attr:`SidSpace.pending`): its reply is awaited;
- **quarantined** (in :attr:`SidSpace.quarantine`): its request was given up on (timed out,
  cancelled, the link failed); free again when its late reply comes (plus a short grace for
  a duplicate of it) or the quarantine ends;
- **lingering** (in :attr:`SidSpace.lingering`): answered, and a duplicate of its reply (the
  network's, or the reply to a retransmission) could still come.

The linger after a reply is learnt from the duplicates the link shows, and ends on evidence:
once no duplicate has come for a quiet span (see :meth:`SidSpace.calm`) it falls back to a
floor, so that a link which stopped duplicating gets its SIDs back.

A fresh socket or connection starts a clean space (:meth:`SidSpace.forget`): nothing late
can reach it. A session owns one space per transport; a destination with several sockets
or connections would own one per socket.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from collections.abc import Set as AbstractSet
from itertools import islice
from time import monotonic
from typing import Any

from ..protocol.guard import changes
from .clock import Clock
from .matching import LATE_REPLY_GRACE, RELAY_LINGER, count_unmatched
from .response import SessionStats
from .slots import DestState, Pending

_NONE: frozenset[int] = frozenset()
#: A duplicate reply seen ``x`` seconds after its request completed makes SIDs linger
#: ``LINGER_FACTOR x x`` after a completion from then on (at most :data:`MAX_LINGER`).
LINGER_FACTOR = 2.0
MAX_LINGER = 5.0
#: On a link that has shown duplicates, a copy of a SID's last reply that comes to the SID's
#: next request (which asked something else) within this many seconds of that reply, or
#: LINGER_FACTOR times the linger, is held back (see :meth:`SidSpace.hold`).
HOLD_WINDOW = 1.0
#: What :attr:`SidSpace.held` notes for a reply held back on a link that has shown no
#: duplicate (the session's ``_first_sign``): nothing is learnt from it.
FIRST_SIGN = -1.0
#: At least this many (at most twice as many) distinct recent replies of a SID space are
#: kept (:attr:`SidSpace.heard`), whatever the SIDs they came under: a copy of any of them
#: within the hold window is a duplicate, told apart from a stray reply. Before the link's
#: first duplicate, a read's reply that is one of them, to another question, is held back
#: once (the first-sign rule: the session's ``_first_sign``); after it, a copy of one of
#: them that came to its SID's new request is held back (the duplicate rule, see
#: :meth:`SidSpace.hold`). A bound per space, not per SID: after an outage a few SIDs may
#: carry every request, and each comes round many times while a copy of one of its replies
#: is on its way (soak seed 1400620: 54 SIDs free, SID 123 reused 14 times in the 65 ms
#: before a copy of its reply came, when 8 replies were kept per SID).
HEARD_REPLIES = 4096
#: The linger of a link that has shown duplicates once none has come for a quiet span
#: (:meth:`SidSpace.calm`), unless ``min_linger`` is longer: above 0, so that what the link
#: showed stays known (the duplicate rule stays on), and short
#: enough that 256 SIDs never run short (256,000 requests a second per destination).
LINGER_FLOOR = 0.001
#: A link's linger lasts while it shows duplicates: once none has come for this many seconds
#: it falls back to :data:`LINGER_FLOOR` (see :meth:`SidSpace.calm`). As long as a linger of
#: 1 s (duplicates 0.5 s late), so that with duplicates up to that late every copy of a reply
#: answered before the last duplicate has come by then; it does not grow with the linger, so
#: that a link that stopped duplicating has its SIDs back within the recovery bound (2 x the
#: timeout + the breaker's longest cooldown) however long its linger grew.
QUIET_SPAN = 1.0
#: Per SID key, the give-ups of this many commands are remembered (:attr:`SidSpace.abandoned`):
#: the request's own and the SID probes' two (which ask another command than it).
ABANDONED_COMMANDS = 4
#: Longest pause between two looks for a free SID while all 256 are taken.
SID_WAIT = 0.01
#: Seconds without a SID shortage after which the next one is a new episode (logged again):
#: at a high rate SIDs come free and run short many times a second within one shortage.
SHORTAGE_EPISODE = 60.0


def may_send_again(idempotent: bool, mrc: int, src: int, params: bytes) -> bool:
    """Whether the duplicate rule may send a request without retries once more, same
    frame and SID, when a reply to it copies one of its SID's earlier replies (see the
    session's ``_hold_copy``): the caller marked it idempotent, or the command changes
    nothing in the PLC (:func:`~aiofins.protocol.guard.changes`: a read), whatever the
    caller said. Asked only on a link that has shown duplicates."""
    return idempotent or changes(mrc, src, params) is None


class SidSpace:
    """The SIDs and the in-flight table of one transport (see the module's docstring).

    ``min_linger`` is the linger after a completion before the link has shown any late
    duplicate; :meth:`unmatched` raises it from what the link shows.
    """

    __slots__ = (
        "abandoned",
        "answers",
        "asked",
        "clock",
        "copy_at",
        "ended",
        "floor",
        "given_up",
        "heard",
        "held",
        "linger",
        "linger_resent",
        "lingering",
        "ours",
        "pending",
        "quarantine",
        "recent",
        "relay_doubt",
        "routed",
        "short_at",
        "slowest",
        "unsure",
    )

    # What the link's duplicates taught (documented here, set in __init__):
    #: SID key -> the frame (what it asked) of the request its last reply answered.
    asked: dict[int, bytes]
    #: SID key -> how late after the SID's previous reply a copy of that reply came to its
    #: new request, held back (the latest, if more than one came), and the replies held
    #: back for that request (see :meth:`hold`; each once: the same bytes again answer it).
    held: dict[int, tuple[float, tuple[bytes, ...]]]
    #: Whether a copy of a reply is held back (:attr:`held`) or SIDs given up on wait for
    #: evidence that their destination answers (:attr:`given_up`): the receive path's one
    #: test for both (the session's ``_unsure``). Set where either changes (:meth:`abandon`,
    #: :meth:`answered_after`, :meth:`hold`, :meth:`hold_first`, :meth:`unhold`,
    #: :meth:`forget`), nowhere else, so never stale; held and given up on change only there.
    unsure: bool
    #: The space's recent replies, each SID's and each destination's: each reply frame (its
    #: bytes hold its SID key) -> ``[when it last came, what its request sent (its frame)]``
    #: (a list: the session updates it in place when the same bytes come again), in the
    #: order first heard; frames kept by reference, not copied. Between
    #: :data:`HEARD_REPLIES` and twice that many frames (see :meth:`hear`): a copy of any
    #: is found without a scan, on every reply (the session's ``_first_sign`` before the
    #: link's first duplicate, ``_held`` after it).
    heard: dict[bytes, list[Any]]
    #: The linger after a completion the link has shown necessary (late duplicates); back
    #: to :attr:`floor` once it has shown none for a while (:meth:`calm`).
    linger: float
    #: The same after a retransmission (learnt from replies to earlier transmissions).
    linger_resent: float
    #: What the linger falls back to (:meth:`calm`): ``min_linger``, at least
    #: :data:`LINGER_FLOOR`.
    floor: float
    #: When the link last showed a duplicate of a reply (``-inf``: never).
    copy_at: float
    #: SID key -> command (MRC << 8 | SRC) -> when a request of it was last given up on
    #: under the key (the last :data:`ABANDONED_COMMANDS` commands): a reply with that
    #: command, byte for byte one the SID carried before, may be that request's late reply,
    #: not a copy (:meth:`late_reply`).
    abandoned: dict[int, dict[int, float]]
    #: SID key -> its request's send (its give-up, if it was sent again), its command,
    #: whether sent once, until when a late reply to it teaches :attr:`slowest` (the
    #: evidence + :data:`~.matching.LATE_REPLY_GRACE`) and when its quarantine's full term
    #: ends, and when it was first sent: a SID whose quarantine the evidence ended early
    #: (:meth:`answered_after`), while that term runs. A longer round trip shown later
    #: extends its quarantine again (:meth:`slower`).
    ended: dict[int, tuple[float, int, bool, float, float, float]]

    def __init__(self, min_linger: float = 0.0, clock: Clock = monotonic) -> None:
        #: The session's clock (see :mod:`.clock`).
        self.clock = clock
        #: SID key -> the request in flight under it.
        self.pending: dict[int, Pending] = {}
        #: SID key -> when it may be used again (requests given up on).
        self.quarantine: dict[int, float] = {}
        #: Destination (its key's upper bytes) -> SID key -> when its request was given up
        #: on, its command (MRC << 8 | SRC), when it was first sent and whether only once,
        #: until the destination answers a request sent after it was given up on (see
        #: :meth:`answered_after`).
        self.given_up: dict[int, dict[int, tuple[float, int, float, bool]]] = {}
        #: ``SID << 16 | command`` -> until when: a SID whose quarantine the evidence rule
        #: ended early (:meth:`answered_after`) while a relay error to its request, which
        #: comes on the relay's timer, may still come; a relay error under that SID number
        #: and command code is taken for that request's (see :meth:`relay_doubted`).
        self.relay_doubt: dict[int, float] = {}
        self.ended = {}
        #: The slowest round trip (seconds) the link has shown, from a request's send to its
        #: reply, of requests sent once (Karn: which transmission a reply answers is
        #: unknown otherwise): answered, or given up on and answered late before any
        #: evidence or within :data:`~.matching.LATE_REPLY_GRACE` of it (see
        #: :meth:`late_round_trip`). A quarantine ends on the evidence that the
        #: destination answers no sooner than :data:`LINGER_FACTOR` times this after its
        #: request was sent (see :meth:`answered_after`), however much it grows later
        #: (:meth:`slower`).
        self.slowest = 0.0
        self.abandoned = {}
        #: SID key -> when it may be used again (answered: a duplicate may follow).
        self.lingering: dict[int, float] = {}
        #: SID key -> when its last request was answered (to count and time duplicates);
        #: negative after a retransmission.
        self.recent: dict[int, float] = {}
        #: SID key -> the reply its last request was answered with: a duplicate is a copy
        #: of it, byte for byte (at most one frame per key: 256 per destination).
        self.answers: dict[int, bytes] = {}
        self.asked = {}
        self.held = {}
        self.unsure = False
        self.heard = {}
        self.linger = min_linger
        self.linger_resent = 0.0
        self.floor = max(min_linger, LINGER_FLOOR)
        self.copy_at = -math.inf
        #: Requests go to more than one destination: a SID is then kept unique across them,
        #: as a relay error (from the relay point, not the destination) is matched by SID.
        self.routed = False
        #: When a request last found every SID of a destination taken (``-inf``: never);
        #: a shortage within :data:`SHORTAGE_EPISODE` of the last is the same episode,
        #: logged once.
        self.short_at = -math.inf
        #: Our address on this space's socket or connection (its source: ``DNA DA1 DA2``
        #: of a reply to it, see :func:`~aiofins.protocol.frames.address_bits`; -1 while
        #: not known). A reply addressed elsewhere never matches this space's requests.
        self.ours = -1

    # -- taking a SID ---------------------------------------------------------------------

    def take(self, state: DestState, now: float) -> int | None:
        """The key of a free SID for ``state``'s destination, next in round-robin order
        (``None``: all 256 are in flight, quarantined or lingering). Cheap when the next
        one is free, as it nearly always is. ``Session.start()`` inlines it: keep the two
        alike."""
        sid = state.cursor
        key = state.keys[sid]  # (see Session.start)
        if (
            key in self.pending
            or key in self.quarantine
            or ((lingering := self.lingering) and lingering.get(key, 0.0) > now)
            or (self.routed and self.sid_taken(key))
        ):
            return self.allocate(state)
        state.cursor = sid + 1 if sid < 255 else 0
        return key

    def sid_taken(self, key: int) -> bool:
        """Whether ``key``'s SID is in flight to another destination, or may still get a
        late relay error (see :meth:`relay_taken`)."""
        sid = key & 0xFF
        return any(k & 0xFF == sid for k in self.pending) or sid in self.relay_taken(self.clock())

    def relay_taken(self, now: float) -> set[int]:
        """The SIDs quarantined or lingering now for any destination, which a request to
        another may not take while the session addresses several (:attr:`routed`). A relay
        error comes from the relay point, not the destination, and is matched by SID and
        command code alone (:func:`~.matching.match_relay_error`); a late one for a request
        given up on, or for an earlier transmission of one answered (a relay error to its
        first attempt after its retransmission was answered), must not find a newer
        request to another destination (routed through that relay, perhaps: the session
        does not know the routes) under the same SID."""
        taken = {k & 0xFF for k, until in self.quarantine.items() if until > now}
        taken.update(k & 0xFF for k, until in self.lingering.items() if until > now)
        return taken

    def is_free(self, key: int, now: float, taken: AbstractSet[int]) -> bool:
        """Whether ``key`` may carry a new request now: not in flight (``taken``: the SIDs in
        flight to other destinations, when routing), quarantined or lingering. Ends a
        quarantine or linger that is over."""
        if key in self.pending or (key & 0xFF) in taken:
            return False
        for table in (self.quarantine, self.lingering):
            until = table.get(key)
            if until is not None:
                if until > now:
                    return False
                del table[key]
        return True

    def allocate(self, state: DestState) -> int | None:
        """The next free SID of ``state`` in round-robin order (``None``: all 256 taken);
        a scan of up to 256 keys."""
        base, sid = state.base, state.cursor
        now = self.clock()
        if self.linger > self.floor and now - self.copy_at >= QUIET_SPAN:
            self.calm(now)
        taken: AbstractSet[int] = _NONE
        if self.routed:
            taken = {k & 0xFF for k in self.pending} | self.relay_taken(now)
        for _ in range(256):
            key = base | sid
            sid = (sid + 1) & 0xFF
            if self.is_free(key, now, taken):
                state.cursor = sid
                return key
        return None

    def calm(self, now: float) -> None:
        """The link has shown no duplicate for :data:`QUIET_SPAN` (1 s): the linger falls
        back to :attr:`floor`, and the SIDs lingering under the link's linger are free
        :attr:`floor` after their reply (a SID a relay error answered:
        :data:`~.matching.RELAY_LINGER` after it); those lingering longer for another
        reason (a reply to a retransmission) keep their linger. The next duplicate
        teaches the linger again at once (:meth:`learn`). Checked when a SID is looked
        for beyond the next in round-robin order (:meth:`allocate`): a linger costs
        nothing until SIDs run short, and a link that stopped duplicating never keeps
        them all taken (issue #22: soak seeds 30117 and 50279 found no free SID long
        after the faults)."""
        old, floor = self.linger, self.floor
        self.linger = floor
        recent, answers, lingering = self.recent, self.answers, self.lingering
        for key, until in lingering.items():
            done_at = recent.get(key)
            if done_at is None or done_at < 0 or until > done_at + old or until <= now:
                continue
            reply = answers.get(key)
            end = done_at + (RELAY_LINGER if reply is not None and reply[12] & 0x80 else floor)
            if end < until:
                lingering[key] = end

    def free_in(self, state: DestState, now: float) -> float:
        """Seconds until the next quarantine or linger of ``state``'s SIDs ends (at least
        1 ms; at most :data:`SID_WAIT`, e.g. when all 256 are in flight)."""
        base = state.base
        soonest = now + SID_WAIT
        for table in (self.quarantine, self.lingering):
            for key, until in table.items():
                if now < until < soonest and key & ~0xFF == base:
                    soonest = until
        return max(soonest - now, 0.001)

    # -- ending a request -----------------------------------------------------------------

    def abandon(self, p: Pending, until: float) -> None:
        """Give up on ``p``: out of the table, its SID quarantined until ``until`` (unless
        its late reply comes first, or the destination answers a request sent after this
        moment: see :meth:`answered_after`)."""
        p.done = True
        p.abandoned = True
        self.pending.pop(p.key, None)
        key = p.key
        if self.held:
            self.held.pop(key, None)
        self.quarantine[key] = until
        self.unsure = True  # (given up on: see given_up)
        if self.ended:
            self.ended.pop(key, None)
        mine = self.given_up.get(key & ~0xFF)
        if mine is None:
            mine = self.given_up[key & ~0xFF] = {}
        now, command = self.clock(), (p.mrc << 8) | p.src
        mine[key] = (now, command, p.sent_at, p.rtt is not None)
        gave = self.abandoned.get(key)
        if gave is None:
            gave = self.abandoned[key] = {}
        else:
            gave.pop(command, None)  # (the newest last)
            if len(gave) >= ABANDONED_COMMANDS:
                del gave[next(iter(gave))]
        gave[command] = now

    def answered_after(self, key: int, sent_at: float, now: float) -> None:
        """The destination of ``key`` answered a request first sent at ``sent_at``: the
        quarantine of each of its SIDs given up on before then ends
        :data:`~.matching.LATE_REPLY_GRACE` from ``now``, or :data:`LINGER_FACTOR` times
        the slowest round trip the link has shown (:attr:`slowest`) after its request was
        sent, whichever is later. The destination answers again, so a command it lost
        (an outage's) will never be answered; but one still on its way, delayed, reaches
        it after the younger one and is answered after it, as late as the link's round
        trips (soak seed 50239: a read given up on after 18 ms, its command 0.40 s on its
        way and its reply 0.25 s, answered a read that reused its SID 0.54 s after the
        younger read's answer). So an outage's quarantines end on the evidence that the
        PLC answers, not ``min_quarantine`` (15 s) later, and a slow link's when a reply
        to their requests could no longer come. Called by the receive path while any SID
        given up on has not seen such evidence (:attr:`given_up`).

        That evidence says nothing of a relay error to an older request: a relay point sends
        it on its own timer, not the destination's, and it may come after the quarantine
        ended so. Each SID whose quarantine ends early is put in doubt for a relay error
        under its number and command code until the quarantine's full term
        (:attr:`relay_doubt`, :meth:`relay_doubted`).

        Nor does it say that a delay episode is over: the link's round trips may be
        growing beyond any it has shown (soak seed 53003: 0.71 s, after 0.34 s at most).
        Each SID whose quarantine ends early is kept in :attr:`ended` until its full
        term: a longer round trip shown before it is reused extends its quarantine again
        (:meth:`slower`)."""
        dest = key & ~0xFF
        mine = self.given_up.get(dest)
        if mine is None:
            return
        end = now + LATE_REPLY_GRACE
        wait = LINGER_FACTOR * self.slowest
        quarantine, doubt, ended = self.quarantine, self.relay_doubt, self.ended
        for k, (at, command, sent, once) in list(mine.items()):
            if at > sent_at:
                continue
            del mine[k]
            until = quarantine.get(k)
            if until is None:
                continue
            # (sent again: its last transmission went out before it was given up on)
            ends = max(end, (sent if once else at) + wait)
            if until > ends:
                quarantine[k] = ends
                if len(ended) >= 1024:  # (bounded: those whose term is over go first)
                    for e in [e for e, v in ended.items() if v[4] <= now] or list(ended)[:1]:
                        del ended[e]
                ended[k] = (sent if once else at, command, once, end, until, sent)
                if len(doubt) >= 256:  # (bounded: the expired go first)
                    for d in [d for d, u in doubt.items() if u <= now] or list(doubt)[:1]:
                        del doubt[d]
                d = (k & 0xFF) << 16 | command
                if doubt.get(d, 0.0) < until:
                    doubt[d] = until
        if not mine:
            del self.given_up[dest]
            self.unsure = bool(self.held or self.given_up)

    def relay_doubted(self, sid: int, command: int, now: float) -> bool:
        """Whether a relay error under ``sid`` for ``command`` (``MRC << 8 | SRC``) is taken
        for the request given up on under that SID whose quarantine ended on the evidence
        that its destination answers (:meth:`answered_after`), rather than for a request
        that took the SID since. A relay error carries the relay's address, not the
        destination's, and no request number, so nothing tells the two apart; the older is
        the one that may come late (the relay-error rule, docs/session.md), and the newer
        gets its own reply or times out. The doubt then ends
        :data:`~.matching.LATE_REPLY_GRACE` (or the linger) later: a copy of that relay
        error may follow."""
        d = sid << 16 | command
        until = self.relay_doubt.get(d)
        if until is None:
            return False
        if until <= now:
            del self.relay_doubt[d]
            return False
        self.relay_doubt[d] = min(until, now + max(LATE_REPLY_GRACE, self.linger))
        return True

    def drain(self) -> list[Pending]:
        """Every request in flight, taken out of the table (the link failed)."""
        pending = list(self.pending.values())
        self.pending.clear()
        return pending

    def fail_all(self, exc: BaseException, until: Callable[[float, float], float]) -> None:
        """Fail every request in flight with ``exc`` (the link failed): each taken out of
        the table and its SID quarantined until ``until(now, time since it was sent)``
        (should the link come back under the same space, a late reply must not reach a
        newer request)."""
        now = self.clock()
        for p in self.drain():
            self.abandon(p, until(now, now - p.sent_at))
            p.fail(exc)

    def forget(self) -> None:
        """A fresh socket or connection: no late reply can reach it, every SID is free."""
        self.quarantine.clear()
        self.given_up.clear()
        self.relay_doubt.clear()
        self.ended.clear()
        self.lingering.clear()
        self.held.clear()
        self.unsure = False
        self.heard.clear()
        self.abandoned.clear()

    def resent_linger(self, p: Pending, now: float, rto_max: float) -> float:
        """How long the SID of ``p``, answered after a retransmission, lingers: a reply to
        one of its other transmissions may still be on its way. At least the largest
        retransmission timeout ``rto_max`` (a round trip longer than that counts as lost),
        twice the time the call took, and the linger the link has shown necessary."""
        return max(self.linger, self.linger_resent, rto_max, LINGER_FACTOR * (now - p.sent_at))

    def unmatched(
        self, stats: SessionStats, key: int, frame: bytes, relay_error: bool = False
    ) -> tuple[str, float]:
        """A reply ``frame`` no request waits for: counted (late, duplicate or
        unsolicited). A late reply ends its SID's quarantine; a duplicate (a copy of the
        reply its SID was last answered with, see :attr:`answers`) teaches the linger
        (SIDs then wait twice its lateness after a reply). Returns which (``"late"``,
        ``"duplicate"`` or ``"unsolicited"``), and for a duplicate of a reply the network
        repeated that made :attr:`linger` grow, how late it came (else 0.0). Anything
        else under an answered SID (a reply with a wrong SID, say) is unsolicited and
        teaches nothing: taken for a duplicate, a stray reply under a SID answered seconds
        ago made every SID linger seconds, and requests wait for SIDs long after the PLC
        answered normally again (issue #22)."""
        now = self.clock()
        grace = max(LATE_REPLY_GRACE, self.linger)
        if relay_error:  # its key is the relay's: a copy is of the SID's last answer
            sid = key & 0xFF
            if (
                self.relay_doubt
                and self.relay_doubted(sid, int.from_bytes(frame[10:12], "big"), now)
                and not any(k & 0xFF == sid for k in self.quarantine)
            ):  # the late relay error of a request given up on, its SID free since
                stats.late_replies += 1
                return "late", 0.0
            key = self.last_answered(key)
        kind, key = count_unmatched(
            stats, self.quarantine, self.answers, key, frame, now, relay_error, grace
        )
        if kind == "late":
            # (not a relay error's: it comes on the relay point's timer, not as a round
            # trip, and its key is any SID quarantined under its number)
            if not relay_error:
                self.late_round_trip(key, frame, now)
        elif kind == "unsolicited" and not relay_error:
            at = self.copy_of_older(frame, now)
            if at is not None and not self.late_reply(key, frame, at):  # a copy of an older
                stats.unsolicited -= 1  # reply than the SID's last one
                stats.duplicates += 1
                return "duplicate", self.learn(now - at, now)
        if kind == "duplicate":
            done_at = self.recent.get(key)
            if done_at is not None and done_at < 0:  # the reply to another transmission
                linger = min(MAX_LINGER, LINGER_FACTOR * (now + done_at))
                if linger > self.linger_resent:
                    self.linger_resent = linger
            elif done_at is not None:
                if not relay_error and self.late_reply(key, frame, done_at):
                    stats.duplicates -= 1
                    stats.late_replies += 1
                    return "late", 0.0
                return kind, self.learn(now - done_at, now)  # the network duplicated a reply
        return kind, 0.0

    def late_round_trip(self, key: int, frame: bytes, now: float) -> None:
        """A late reply ``frame`` came ``now`` under ``key``, quarantined: the round trip it shows
        (from its request's send) makes :attr:`slowest`, if longer (:meth:`slower`). If that
        request was sent more than once, the reply to another transmission may follow: its
        SID waits for it (:meth:`resent_late`) and nothing is learnt (which transmission it
        answers is unknown). Only if the request given up on under ``key`` was sent once and
        asked the command ``frame`` answers, and while it has seen no evidence
        (:attr:`given_up`) or within :data:`~.matching.LATE_REPLY_GRACE` of the evidence
        that ended its quarantine (:attr:`ended`): a reply the PLC sends under a wrong SID
        is taken for the late reply of any quarantined SID, and one that came in the term
        the evidence left a quarantine (twice :attr:`slowest`) taught a round trip twice as
        long each time (a simulated PLC answering under wrong SIDs after a delay of 0.4 s:
        3 s). The grace after the evidence does not grow with :attr:`slowest`: a wrong SID's
        reply within it shows no longer than the wait for the evidence (an outage's length),
        plus the grace and the request's timeout."""
        mine = self.given_up.get(key & ~0xFF)
        if mine is not None and (given := mine.get(key)) is not None:
            if not given[3]:  # (out of given_up: the evidence must not end what it waits)
                del mine[key]
                if not mine:
                    del self.given_up[key & ~0xFF]
                    self.unsure = bool(self.held or self.given_up)
                self.resent_late(key, given[2], now)
                return
            command = frame[10] << 8 | frame[11]
            if command == given[1] and now - given[2] > self.slowest:
                self.slower(now - given[2], now)
            return
        ended = self.ended.pop(key, None) if self.ended else None
        if ended is None:
            return
        if not ended[2]:
            self.resent_late(key, ended[5], now)
            return
        if now > ended[3]:
            return
        if ended[1] != (frame[10] << 8 | frame[11]):
            return
        if now - ended[0] > self.slowest:
            self.slower(now - ended[0], now)

    def resent_late(self, key: int, first_sent: float, now: float) -> None:
        """A late reply came ``now`` under ``key``, quarantined, whose request was sent
        more than once, first at ``first_sent``: the reply to another transmission may
        still come, so the SID waits as long as one answered after a retransmission
        lingers (:meth:`resent_linger`, without the retransmission timeout): twice the
        time since the first send, or the linger replies to other transmissions have
        shown (:attr:`linger_resent`), if longer than the grace the late reply gave
        (at most :data:`MAX_LINGER`). Soak seed 60380: a read sent at 1.230 s and again
        at 1.250 s, given up on; the reply to one came at 1.512 s, the quarantine ended
        0.5 s later, and the other's, 0.77 s on its way in a delay episode, answered a
        read that had taken the SID at 2.017 s."""
        wait = min(MAX_LINGER, max(self.linger_resent, LINGER_FACTOR * (now - first_sent)))
        quarantine = self.quarantine
        if quarantine.get(key, now) < now + wait:
            quarantine[key] = now + wait

    def slower(self, round_trip: float, now: float) -> None:
        """The link showed a round trip of ``round_trip`` seconds, longer than
        :attr:`slowest`: it becomes :attr:`slowest`, and each quarantine the evidence
        ended early (:attr:`ended`) lasts again until :data:`LINGER_FACTOR` times it after
        its request was sent (within its full term), unless its SID was reused since.
        The evidence says nothing of a delay episode that began before it: its first
        late replies, or a reply in time, show round trips longer than the link had shown
        (soak seed 53003: a read given up on, its quarantine ended on a younger read's
        answer 0.68 s after its send, the link having shown 0.34 s at most, was answered
        0.71 s after its send, under the SID reused by a read of as many words). Called
        by the receive path only when the round trip is the longest yet."""
        self.slowest = round_trip
        if not self.ended:
            return
        wait, quarantine, pending = LINGER_FACTOR * round_trip, self.quarantine, self.pending
        for k, (sent, _, _, _, until, _) in list(self.ended.items()):
            if until <= now or k in pending:  # (over, or reused: see "Guarantees")
                del self.ended[k]
            elif (ends := min(until, sent + wait)) > now and quarantine.get(k, 0.0) < ends:
                quarantine[k] = ends

    def late_reply(self, key: int, frame: bytes, since: float) -> bool:
        """Whether ``frame``, byte for byte a reply the SID of ``key`` carried at ``since``,
        may instead be the late reply to a request given up on under ``key`` after that
        with the same command (:attr:`abandoned`): a write's reply is the same bytes every
        time, and so is a read's of values that did not change. Then it is no evidence of
        a duplicate and teaches no linger: taken for one, the late reply to a request given
        up on in an outage (after its quarantine ended on the evidence that the PLC
        answers, or under the SID probe's other command) taught a linger of seconds
        (issue #22: soak seed 30117, 0.8 and 1.8 s)."""
        gave = self.abandoned.get(key)
        return gave is not None and gave.get((frame[10] << 8) | frame[11], since) > since

    def copy_of_older(self, frame: bytes, now: float) -> float | None:
        """When the reply came that ``frame``, which no request waits for, is
        a copy of, byte for byte: one the space heard (:attr:`heard`) within the hold
        window (:meth:`copied`). ``None``: none (unsolicited). A copy of an older reply than
        the SID's last is the network's duplicate as surely as one of the last; at a high
        rate the SID has most often carried newer requests by the time it comes."""
        found = self.copied(frame, now)
        return found[0] if found is not None else None

    def mismatched(self, stats: SessionStats, key: int, frame: bytes) -> float | None:
        """A reply ``frame`` under ``key`` whose command code (or ICF) is not that of the
        request in flight under it: a copy, byte for byte, of a reply the SID carried
        before (its last, or an earlier one: :meth:`copy_of_older`) is the network's
        duplicate, which came after the SID was reused for another command: counted as a
        duplicate, it teaches the linger (returns what :meth:`learn` does; 0.0 for a copy
        of the reply to a retransmission). Anything else is counted as mismatched
        (``None``), a reply that may be the late one of a request given up on under the
        SID included (:meth:`late_reply`: the SID probe asks another command than the
        request it was given up on for this)."""
        now = self.clock()
        at: float | None
        if self.answers.get(key) == frame:
            at = self.recent.get(key)
            if at is not None and at < 0:  # (the reply to another transmission)
                stats.duplicates += 1
                return 0.0
        else:
            at = self.copy_of_older(frame, now)
        if at is None or self.late_reply(key, frame, at):
            stats.mismatched += 1
            return None
        stats.duplicates += 1
        return self.learn(now - at, now)

    def last_answered(self, key: int) -> int:
        """The key of the request last answered under ``key``'s SID number, any
        destination (``key`` itself if none): a relay error carries the relay's address,
        and a copy of one is a copy of the answer to that request. (While the session
        addresses several destinations a SID is in flight to one at a time, so its last
        answer is its last use's.) A scan of :attr:`recent`: for relay errors no request
        waits for."""
        sid = key & 0xFF
        last, when = key, -1.0
        for k, done_at in self.recent.items():
            if k & 0xFF == sid and abs(done_at) > when:
                last, when = k, abs(done_at)
        return last

    def learn(self, lateness: float, now: float) -> float:
        """A duplicate came ``lateness`` seconds after the reply it copies (noted: the
        linger lasts while duplicates come, see :meth:`calm`): the linger grows to
        :data:`LINGER_FACTOR` times that (at most :data:`MAX_LINGER`) if longer. Returns
        ``lateness`` if it grew, else 0.0."""
        self.copy_at = now
        linger = min(MAX_LINGER, LINGER_FACTOR * lateness)
        if linger <= self.linger:
            return 0.0
        self.linger = linger
        self.extend_lingers(now)
        return lateness

    def remember(self, key: int, frame: bytes, now: float, asked: bytes) -> None:
        """``key``'s SID, which lingers, was answered ``now`` with ``frame`` to a request
        whose frame was ``asked``: kept in :attr:`asked` and :attr:`heard` (:meth:`hear`).
        At a high rate a SID comes round several times while a copy of one of its replies
        may still come."""
        self.asked[key] = asked
        self.hear(frame, now, asked)

    def hear(self, frame: bytes, now: float, asked: bytes) -> None:
        """A reply ``frame`` came ``now`` to a request whose frame was ``asked``: kept in
        :attr:`heard` (the session updates the entry of bytes heard before in place, on a
        link that has shown no duplicate: keep the two alike)."""
        (heard := self.heard)[frame] = [now, asked]
        if len(heard) > 2 * HEARD_REPLIES:
            self.forget_heard()

    def forget_heard(self) -> None:
        """:attr:`heard` holds twice :data:`HEARD_REPLIES` frames: the first half heard go
        (a frame heard again keeps its first place: what it asked last is kept)."""
        self.heard = dict(islice(self.heard.items(), HEARD_REPLIES, None))

    def copied(self, frame: bytes, now: float) -> tuple[float, bytes] | None:
        """When the reply that ``frame`` is a copy of, byte for byte, came (under its SID),
        and the frame of the request it answered: one the space heard (:attr:`heard`; the
        frame holds its key, SNA SA1 SA2 SID, so it is the SID's), the last time those
        bytes came, within the hold window (:data:`HOLD_WINDOW`, or :data:`LINGER_FACTOR`
        times the linger). ``None``: none."""
        heard = self.heard.get(frame)
        if heard is None or now - heard[0] >= max(HOLD_WINDOW, LINGER_FACTOR * self.linger):
            return None
        return float(heard[0]), heard[1]

    def hold(self, key: int, now: float, frame: bytes, done_at: float | None = None) -> bool:
        """A reply ``frame`` under ``key`` that is a copy, byte for byte, of a reply the
        SID was answered with (the last, or ``done_at``: an earlier one of
        :attr:`heard`) came to the SID's new request, which asked something else than
        the last (than an earlier one: anything): whether it is held back rather than
        answer it (noted in :attr:`held`; see the session's ``_hold_copy``). Held when no
        reply with these bytes was held for that request yet and it came within
        :data:`HOLD_WINDOW`, or :data:`LINGER_FACTOR` times the linger, of that reply
        (later than the linger, a duplicate may find the SID reused). A second copy, of
        another of the SID's replies, is held too (soak seed 220447: copies of the SID's
        last two replies, both before the request's own, the second took for its answer);
        the same bytes again answer (a new reply that holds them: never a loop)."""
        noted = self.held.get(key)
        if noted is not None and frame in noted[1]:
            return False  # held once: the same bytes again answer
        if done_at is None:
            done_at = self.recent.get(key)
            if done_at is None:
                return False
        lateness = now - abs(done_at)
        if lateness >= HOLD_WINDOW and lateness >= LINGER_FACTOR * self.linger:
            return False
        if noted is None:
            self.held[key] = (lateness, (frame,))
        else:
            self.held[key] = (max(lateness, noted[0]), (*noted[1], frame))
        self.unsure = True
        return True

    def hold_first(self, key: int, frame: bytes) -> None:
        """A reply ``frame`` under ``key`` held back on a link that has shown no duplicate
        (the first-sign rule: the session's ``_first_sign``): noted in :attr:`held` as
        :data:`FIRST_SIGN` (or as late as a copy held before), nothing learnt from it."""
        noted = self.held.get(key)
        if noted is None:
            self.held[key] = (FIRST_SIGN, (frame,))
        else:
            self.held[key] = (noted[0], (*noted[1], frame))
        self.unsure = True

    def was_held(self, key: int, frame: bytes) -> bool:
        """Whether a reply with the bytes of ``frame`` was held back for the request
        under ``key`` (:attr:`held`): the same bytes again answer it."""
        noted = self.held.get(key)
        return noted is not None and frame in noted[1]

    def unhold(self, key: int) -> float | None:
        """The request under ``key`` is answered: what :attr:`held` noted for it (how
        late the latest copy held back came, or :data:`FIRST_SIGN`), no longer noted;
        ``None`` if nothing was held for it."""
        noted = self.held.pop(key, None)
        if noted is None:
            return None
        if not self.held:
            self.unsure = bool(self.given_up)
        return noted[0]

    def extend_lingers(self, now: float) -> None:
        """The linger grew (a duplicate came later than it): the SIDs answered within the
        new linger, free again or about to be under the old one, linger the new one too,
        from when they were answered. A duplicate of their replies may be as late as this
        one; without this, a SID answered just before the duplicate was seen could be
        reused under the old linger and take a later duplicate of its old reply for the
        new request's (issue #22, defect 5: another read's words after a SID wrap)."""
        linger = self.linger
        lingering, pending = self.lingering, self.pending
        for key, done_at in self.recent.items():
            if done_at > 0 and now - done_at < linger and key not in pending:
                until = done_at + linger
                if lingering.get(key, 0.0) < until:
                    lingering[key] = until
