"""The session: link state, SIDs, the in-flight table, deadlines, retransmission, matching.

Hot path (one request): take a slot of the destination, pick a SID, build the frame from a
pre-built header prefix, register the request in one dict keyed by the 32-bit
``SNA SA1 SA2 SID`` the reply will carry, push its deadline on one structure, send, await
one future. The transport pushes each reply to :meth:`Session.frame_received`, which finds
the request with a single dict lookup and resolves its future. No task and no timer per
request: one watcher task sleeps until the earliest deadline, and retransmits (same frame,
same SID) or gives up what is due.
"""

from __future__ import annotations

import asyncio
import logging
from asyncio import InvalidStateError
from collections.abc import Callable, Sequence
from functools import partial
from struct import error as StructError
from time import monotonic
from types import TracebackType
from typing import Any, NoReturn

import anyio
from anyio.abc import TaskGroup

from ..hooks import (
    EventHooks,
    RequestSent,
    ResponseReceived,
)
from ..protocol.endcodes import CPU_ERROR_FLAGS, END_CODE_MASK, EndCode
from ..protocol.errors import (
    ConnectionLost,
    EndCodeError,
    FinsError,
    FinsTimeout,
)
from ..protocol.frames import (
    ADDRESS_MASK,
    BUSY_CODES,
    ERROR_BITS,
    MIN_RELAY_REPLY_SIZE,
    RELAY_ERROR_BIT,
    RESPONSE_ICFS,
    address_bits,
    check_command,
    end_code_error,
    header_prefix,
    key_address,
    pack_head,
    same_address,
    unpack_reply_head,
)
from ..protocol.guard import changes
from ..protocol.header import DEFAULT_GCT, MAX_PARAMETER_SIZE, FinsAddress
from ..transport.base import Transport, is_asyncio
from .background import Background
from .batch import BatchPending, raise_after_a_turn, request_many
from .breaker import BreakerState, CircuitBreaker, admit_call, call_answered, call_ended
from .clock import Clock, Clocks, backend_clocks
from .link import Link
from .log import cpu_flags_seen, log_duplicate, log_frame, log_unmatched
from .matching import RELAY_LINGER, match_relay_error, match_wildcard
from .messages import no_response
from .options import check_call, check_options
from .response import (
    RING_MASK,
    Response,
    SessionStats,
    _new,
    _set_data,
    _set_end_code,
    _set_frame,
    response_of,
)
from .sids import FIRST_SIGN, HOLD_WINDOW, SidSpace, may_send_again
from .slots import (
    AsyncioPending,
    DestState,
    EventPending,
    HeldPending,
    Pending,
    SlotQueue,
)
from .spaces import ExtraSpace, InFlight, SidSpaces, start_when_free
from .states import LinkState
from .watcher import DeadlineWatcher, Expired

logger = logging.getLogger("aiofins.session")
_DEBUG = logging.DEBUG
#: logging's own record of what ``logger.isEnabledFor(level)`` answered, which logging
#: empties on any change of level (``setLevel``, ``logging.disable``): read before asking,
#: a dict lookup where the call costs several (``{}``, always asking, if logging keeps none).
_ENABLED: dict[int, bool] = getattr(logger, "_cache", {})

_CLOSED_BREAKER = BreakerState.CLOSED
#: The round trip is sampled on one reply in ``_SAMPLE_MASK + 1`` (and on the first ones).
_SAMPLE_MASK = 7
_NORMAL = EndCode(0)
_ICFS = RESPONSE_ICFS  # (short names for the receive path's one test)
_RELAY = RELAY_ERROR_BIT
_Space = ExtraSpace | None  # (frame_received's signature on one line: its def is at 60)
#: Requests completed in a row without an event-loop pass before one is made to wait.
_POLL_STREAK = 32
#: At most this many requests skip the read-after-send after it found nothing.
_POLL_MAX_BACKOFF = 64


def _event_pending() -> Pending:
    """A request's record woken through an anyio event (trio, other backends)."""
    return EventPending(0, 0, 0)


class Session:
    """Multiplexes FINS requests over one transport.

    Use as ``async with Session(transport, source=..., dest=...) as s: await s.request(...)``.

    ``timeout`` bounds a whole call: waiting for the link, for a slot and a SID, every
    transmission and the wait for the reply. Requests that may be retried (reads,
    ``idempotent=True``; others only if the caller passes ``retries``) are sent again with
    the same frame and SID up to ``retries`` times, each after the destination's adaptive
    retransmission timeout (RFC 6298 from measured round trips, within ``rto_bounds``,
    doubling per retransmission; over a reliable stream, FINS/TCP, the call's share
    instead); the last attempt waits until the call's deadline.
    ``attempt_timeout`` caps each attempt's wait instead, for those who want it.

    A SID given up on stays quarantined until its late reply comes, or for
    ``max(quarantine_factor x timeout, min_quarantine)`` seconds. An answered SID lingers
    (is not reused) while a duplicate of its reply could still come: ``min_linger`` at
    least, longer after a retransmission (one retransmission timeout) or once the link has
    shown late duplicates (twice the latest seen). When every SID of the transport is taken,
    the session opens another SID space (another UDP socket with a source node of its own,
    another FINS/TCP connection; see :mod:`aiofins.session.spaces`) rather than reuse one
    early, up to ``max_sid_spaces`` in all (default: the transport's,
    ``transport.default_sid_spaces``). End codes 2604/2605 (busy) are retried
    ``busy_retries`` times with a growing pause, as the command was not executed.

    After ``breaker_threshold`` calls in a row that got no answer (0: never) calls fail at
    once with :class:`CircuitOpen` while one probe at a time tests the link (see
    :mod:`aiofins.session.breaker`). ``hooks`` receive the request and link events.

    Every time the session reads comes from ``clock`` (default: the running event loop's,
    chosen on entry; see :mod:`aiofins.session.clock`), so it runs on virtual time under a
    virtual clock; a driver without an event loop passes its own.
    """

    def __init__(
        self,
        transport: Transport,
        *,
        source: FinsAddress,
        dest: FinsAddress,
        gct: int = DEFAULT_GCT,
        max_in_flight: int = 5,
        timeout: float = 2.0,
        retries: int = 2,
        attempt_timeout: float | None = None,
        rto_bounds: tuple[float, float] = (0.02, 1.0),
        min_linger: float = 0.0,
        max_sid_spaces: int | None = None,
        busy_retries: int = 3,
        busy_backoff: float = 0.01,
        quarantine_factor: float = 2.0,
        min_quarantine: float = 15.0,
        reconnect_backoff: tuple[float, float] = (0.05, 5.0),
        breaker_threshold: int = 5,
        breaker_cooldown: tuple[float, float] = (0.05, 2.0),
        hooks: EventHooks | None = None,
        clock: Clock | None = None,
    ) -> None:
        max_sid_spaces = check_options(
            gct=gct,
            max_in_flight=max_in_flight,
            timeout=timeout,
            attempt_timeout=attempt_timeout,
            retries=retries,
            busy_retries=busy_retries,
            breaker_threshold=breaker_threshold,
            busy_backoff=busy_backoff,
            quarantine_factor=quarantine_factor,
            min_quarantine=min_quarantine,
            min_linger=min_linger,
            max_sid_spaces=max_sid_spaces,
            default_sid_spaces=transport.default_sid_spaces,
            reconnect_backoff=reconnect_backoff,
            breaker_cooldown=breaker_cooldown,
            rto_bounds=rto_bounds,
        )
        self.transport = transport
        self.source = source
        self.dest = dest
        self.gct = gct
        self.timeout = timeout
        self.retries = retries
        self.attempt_timeout = attempt_timeout
        self.rto_bounds = rto_bounds
        self.min_linger = min_linger
        self.busy_retries = busy_retries
        self.busy_backoff = busy_backoff
        self.quarantine_factor = quarantine_factor
        self.min_quarantine = min_quarantine
        self.reconnect_backoff = reconnect_backoff
        self.hooks = hooks
        self._compose(max_in_flight, max_sid_spaces, breaker_threshold, breaker_cooldown, clock)

    def _compose(
        self,
        max_in_flight: int,
        max_sid_spaces: int,
        breaker_threshold: int,
        breaker_cooldown: tuple[float, float],
        clock: Clock | None,
    ) -> None:
        """The session's own state (its clock, SIDs, destinations, the request path's
        switches), then its parts (:meth:`_compose_parts`)."""
        transport = self.transport
        self._hooks = None if self.hooks is None else self.hooks.or_none()
        #: The clock the caller passed (``None``: the event loop's, chosen on entry).
        self._clock_given = clock
        #: The one clock every part of the session reads (see :mod:`.clock`): set on entry
        #: by :meth:`_use_clock`; until then the monotonic clock.
        self.clock: Clock = monotonic if clock is None else clock
        #: Whether retransmissions follow the measured RTO: not over a reliable stream
        #: (FINS/TCP), which loses nothing; there the call's own schedule alone.
        self.adaptive = not transport.reliable
        limit = transport.max_in_flight
        self.max_in_flight = min(max_in_flight, limit) if limit else max_in_flight
        #: One request on the line at a time across all destinations (serial links).
        self._shared_slots = limit == 1
        #: The SIDs and the requests in flight of the transport (see :mod:`.sids`).
        self.sids = SidSpace(self.min_linger, self.clock)
        source = self.source
        self.sids.ours = address_bits(source.network, source.node, source.unit)
        # The space's tables under the names the receive path and tests use.
        self._pending = self.sids.pending
        self._quarantine = self.sids.quarantine
        self._lingering = self.sids.lingering
        self._linger_logged = 0.001  # the linger last logged (logged again once doubled)
        self._dests: dict[FinsAddress, DestState] = {}
        self._slots: dict[Any, SlotQueue] = {}
        self._last_dest: FinsAddress | None = None
        self._last_state: Any = None
        self._tg: TaskGroup | None = None
        self._background: Background | None = None
        self._asyncio = False
        self._loop: Any = None  # the running asyncio loop, if any
        #: Makes the future a request awaits under asyncio (see __aenter__).
        self._new_future: Any = None
        #: Makes the request of a session with no asyncio loop (see :meth:`_pending_made`).
        self._other_pending: Callable[[], Pending] = HeldPending
        self._flags_logged = 0  # CPU error flags (0040/0080) already logged
        #: Whether each frame sent and received is logged (DEBUG): asked of logging once per
        #: call and once per burst of a batch (see :meth:`log_frames`), not per frame.
        self._log_frames = logger.isEnabledFor(_DEBUG)
        self._poll_skip = self._poll_backoff = self._poll_streak = 0
        self._turn_due = False  # the next request yields to the event loop first
        self._compose_parts(max_sid_spaces, breaker_threshold, breaker_cooldown)

    def _compose_parts(
        self, max_sid_spaces: int, breaker_threshold: int, breaker_cooldown: tuple[float, float]
    ) -> None:
        """The parts the session composes: breaker, deadline watcher, counters, extra SID
        spaces, link. Each is handed what it needs; none imports this module."""
        transport = self.transport
        self._breaker = CircuitBreaker(breaker_threshold, breaker_cooldown)
        #: The one timer: retransmits or gives up the requests that are due.
        self._watcher = DeadlineWatcher(self, self._breaker, self._hooks)
        self._deadlines = self._watcher.deadlines
        self._fifo = self._watcher.fifo  # the in-order part, appended to inline
        self._heap = self._deadlines.heap  # the rest (see Deadlines)
        in_flight = InFlight(self.sids.pending)
        self.stats = SessionStats(in_flight)
        #: Requests awaiting a reply (read by datagram transports to stop draining early).
        self.replies_awaited = self._pending
        #: The SID spaces opened when the transport's own are all taken (see .spaces).
        self.spaces = SidSpaces(
            transport,
            max_sid_spaces,
            self.min_linger,
            self.stats,
            self._hooks,
            self.sids,
            received=self.frame_received,
            dropped=self.frame_dropped,
            fail=self._fail_space,
            prefix=self._prefix_from,
        )
        in_flight.spaces = self.spaces.extra
        #: The link: its state, connection attempts, the reconnect backoff.
        self._link = Link(
            transport,
            self,
            self.stats,
            self.reconnect_backoff,
            self._hooks,
            self._adopt_local_node,
            self.sids.forget,
            self.fail_all,
            self.clock,
        )

    # ----------------------------------------------------------------- link state

    @property
    def link_state(self) -> LinkState:
        """Where the link stands (see :class:`LinkState`)."""
        return self._link.state

    @property
    def breaker_state(self) -> BreakerState:
        """The circuit breaker's state (see :class:`BreakerState`)."""
        return self._breaker.state

    @property
    def closed(self) -> bool:
        return self._link.state is LinkState.SHUT

    @property
    def max_sid_spaces(self) -> int:
        """SID spaces (sockets or connections) the session opens at most, its own included."""
        return self.spaces.limit

    @property
    def sid_spaces(self) -> int:
        """SID spaces open now (or opening), the session's own included."""
        return 1 + len(self.spaces.extra)

    # ----------------------------------------------------------------- lifecycle

    async def __aenter__(self) -> Session:
        self._asyncio = is_asyncio()
        if self._asyncio:
            self._loop = loop = asyncio.get_running_loop()
            self._new_future = loop.create_future
            if type(loop).create_future is asyncio.BaseEventLoop.create_future:
                # asyncio's own: the same future, made without that method's Python call.
                self._new_future = partial(asyncio.Future, loop=loop)
            self._watcher.loop = self._loop
        else:
            self._other_pending = _event_pending  # woken through an anyio event
        self._use_clock(backend_clocks(self._clock_given))
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        background = Background(tg, self._link.background_failed, self._watcher.from_task)
        self._background = self._link.background = self._watcher.background = background
        self.spaces.background = background
        try:
            background.start_soon(self._watcher.run)
            await self._link.ensure_open()
        except BaseException as exc:
            await self.aclose()
            self._tg = None
            await tg.__aexit__(None, None, None)
            raise exc
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        await self.aclose()
        tg = self._tg
        if tg is not None:
            self._tg = None
            # Our own tasks are cancelled by now; let the caller's exception pass unwrapped.
            await tg.__aexit__(None, None, None)
        return None

    async def aclose(self) -> None:
        """Fail every request in flight or queued with :class:`ConnectionLost`; close."""
        if not self._link.shut():
            return
        self.fail_all(ConnectionLost(f"session to {self.transport.description} closed"))
        for q in self._slots.values():
            q.fail_waiters(ConnectionLost("session closed"))
        if self._background is not None:
            self._background.cancel_all()
        with anyio.CancelScope(shield=True):
            await self.transport.aclose()
            await self.spaces.aclose()

    def _use_clock(self, clocks: Clocks) -> None:
        """The one place the session's clock is set: every part reads ``clocks.session``,
        the deadline watcher sets its timer in ``clocks.timer`` (see :mod:`.clock`)."""
        clock = self.clock = clocks.session
        self.sids.clock = clock
        self._link.clock = clock
        self.spaces.clock = clock
        self._watcher.clock = clock
        self._watcher.timer_clock = clocks.timer
        self._watcher.direct = clocks.direct

    def _adopt_local_node(self) -> None:
        """The transport is open: take the node the peer assigned us (FINS/TCP), if any, as
        our source node (a node no FINS header can carry fails the connection attempt)."""
        node = self.transport.local_node
        if node is not None and node != self.source.node:
            if not 1 <= node <= 254:
                raise ConnectionLost(
                    f"{self.transport.description} assigned us FINS node {node}: "
                    "not a node number (1..254)"
                )
            self.source = FinsAddress(self.source.network, node, self.source.unit)
            self.sids.ours = address_bits(self.source.network, self.source.node, self.source.unit)
            for state in self._dests.values():
                state.prefix = self._prefix(state.address)
        self.spaces.primary_opened(self.source.node)

    # ----------------------------------------------------------------- transport sink

    def frame_received(self, frame: bytes, _addr: object = None, space: _Space = None) -> None:
        """A whole frame received (``space``: an extra space's, ``_addr`` unused); never raises."""
        if self._log_frames:
            log_frame(self.transport.description, "received", frame)
        try:
            icf, to, key, mrc, src, raw = unpack_reply_head(frame)
        except StructError:  # shorter than a reply's header, command code and end code
            return self._malformed()
        sids = self.sids if space is None else space.sids
        if to & ADDRESS_MASK != sids.ours and self._misdirected(frame, to, sids):
            return
        p = (pending := sids.pending).pop(key, None)
        linger, h = sids.linger, None  # (h: a reply the space heard with these bytes)
        if p is None or mrc != p.mrc or src != p.src or icf not in _ICFS or raw >= _RELAY:
            p, linger = self._matched(frame, p, key, icf, mrc, src, raw, sids, linger)
            if p is None:
                return
        elif (linger or ((h := sids.heard.get(frame)) is not None and h[1] != p.frame)) and (
            self._held(p, key, frame, sids)
        ):
            return  # (a copy of a reply of the SID, held back: see _hold_copy, _first_sign)
        key = p.key  # (its own: one DestState.keys object, not the int read from the frame)
        clock = self.clock  # (called from a local: a callable attribute's call is not cached)
        p.done, p.end_code, now = True, raw, clock()
        if ((latency := now - p.sent_at) > sids.slowest and p.rtt is not None) or sids.unsure:
            self._unsure(sids, p, key, frame, latency, now)  # (a slowest round trip, or doubt)
        sids.recent[key], sids.answers[key] = now, frame
        stats = self.stats  # latency bookkeeping inlined: this runs once per reply
        stats._lat_count = (n := stats._lat_count) + 1
        stats._lat_sum += latency
        stats._lat_ring[n & RING_MASK] = latency
        if (r := p.rtt) is not None and not n & _SAMPLE_MASK:  # every 8th: once per RTT
            r.sample(latency, self.rto_bounds if self.adaptive else None)  # (RFC 6298)
        if r is None or linger:  # before the wake-up: a batch sends its next command inside it
            self._lingers(sids, p, key, frame, now, linger)
        elif h is not None:  # (bytes heard before: SidSpace.heard, what they answered set
            h[0] = now  # by _first_sign if not the same; what a copy may be of, kept in place)
        else:
            sids.hear(frame, now, p.frame)
        if (fut := p.fut) is not None:
            try:  # noqa: SIM105 (no context manager: once per reply)
                fut.set_result(frame)
            except InvalidStateError:  # (cancelled: the caller cleans up as it resumes)
                pass
        elif type(p) is AsyncioPending:  # answered before its caller waits: no future
            p.reply = frame
        else:
            p.wake(frame)
            if self._hooks is None and type(p) is BatchPending and p.batch.remaining:
                return  # its batch drops the answered from the deadlines per burst (drop_answered)
        if (hooks := self._hooks) is not None and hooks.response_received:
            self.emit(hooks.response_received, ResponseReceived, p, raw, latency, p.attempts)
        if (fifo := self._fifo) and fifo[0].done:  # the answered at the deadlines' front
            fifo.popleft()
            while fifo and fifo[0].done:
                fifo.popleft()
            if self._heap or (not fifo and self._watcher.disarms):  # (a pile-up: an unanswered
                self._deadlines_left(len(pending))  # front's reply: see _deadlines_left)
        elif self._heap or (len(fifo) > 64 + 4 * len(pending) if fifo else self._watcher.disarms):
            self._deadlines_left(len(pending))

    def drop_answered(self) -> None:
        """What :meth:`frame_received` does with the deadlines after a reply: the answered
        requests at the front of the FIFO dropped, the rest (:meth:`_deadlines_left`) when
        needed. A batch's reply with more of the batch to come (and no hooks) leaves this
        to its batch, which calls it once per burst (:meth:`Batch.flush
        <aiofins.session.batch.Batch.flush>`), and as it ends; its last reply does it."""
        fifo = self._fifo
        while fifo and fifo[0].done:
            fifo.popleft()
        pending = self.sids.pending
        if self._heap or (len(fifo) > 64 + 4 * len(pending) if fifo else self._watcher.disarms):
            self._deadlines_left(len(pending))

    def _malformed(self) -> None:
        """A frame shorter than a reply's head came: counted, dropped (never raised)."""
        self.stats.malformed += 1

    def _lingers(
        self, sids: SidSpace, p: Pending, key: int, frame: bytes, now: float, linger: float
    ) -> None:
        """``p`` answered by ``frame`` ``now`` on a link with a ``linger`` (the link's, or a
        relay error's), or after it was sent again (``p.rtt`` is ``None``: a reply to
        another transmission may follow, so its SID lingers as long as that needs): its
        SID lingers, and its reply is remembered with what it asked (for :meth:`_hold_copy`)."""
        if p.rtt is None:  # sent again
            linger = max(linger, sids.resent_linger(p, now, self.rto_bounds[1]))
            sids.recent[key] = -now  # (negative: its duplicates teach this linger only)
        if linger:
            sids.lingering[key] = now + linger
            sids.remember(key, frame, now, p.frame)

    def _deadlines_left(self, in_flight: int) -> None:
        """After a reply, when the deadlines need more than dropping the answered requests
        at the front of their FIFO: compacted when some stay out of order (the heap) or a
        slow request keeps many answered ones behind it; with no deadline left, the
        watcher's timer cancelled if it fires for nothing (:attr:`DeadlineWatcher.disarms`)."""
        if self._heap or len(self._fifo) > 64 + 4 * in_flight:
            self._deadlines.prune(in_flight)
        elif not self._fifo and self._watcher.disarms:
            self._watcher.disarm()

    def _matched(
        self,
        frame: bytes,
        p: Pending | None,
        key: int,
        icf: int,
        mrc: int,
        src: int,
        raw: int,
        sids: SidSpace,
        linger: float,
    ) -> tuple[Pending | None, float]:
        """The request a reply answers when it is not simply the one under its key
        (``p``, taken out of ``sids``' pending table, if any): one sent to a wildcard
        address, or the one a relay error names (see :meth:`_match_other`); ``None`` (put
        back, counted) when its command code or ICF shows the reply is not its, a relay
        error is too short to say where it comes from, or the reply is held back (see
        :meth:`_held`). With it, how long its SID lingers (``linger``, the link's): a relay
        error is never held back (a new one is byte for byte the old one), and its SID
        lingers at least :data:`~.matching.RELAY_LINGER` (see "The relay-error rule")."""
        pending = sids.pending
        if p is None:
            p = self._match_other(frame, key, raw, sids)
            if p is None:
                return None, linger
            key = p.key
            del pending[key]
        if mrc != p.mrc or src != p.src or icf not in RESPONSE_ICFS:
            pending[key] = p
            if (grew := sids.mismatched(self.stats, key, frame)) is not None:  # a copy
                where = self.transport.description
                self._linger_logged = log_duplicate(
                    where, self.spaces, sids, key, grew, self._linger_logged
                )
            return None, linger
        if raw >= RELAY_ERROR_BIT:
            if len(frame) < MIN_RELAY_REPLY_SIZE:
                pending[key] = p
                self.stats.malformed += 1
                return None, linger
            if sids.relay_doubt and sids.relay_doubted(key & 0xFF, mrc << 8 | src, self.clock()):
                pending[key] = p  # the late relay error of an older request under the SID
                self.stats.late_replies += 1
                return None, linger
            return p, max(linger, RELAY_LINGER)
        if (linger or frame in sids.heard) and self._held(p, key, frame, sids):
            return None, linger
        return p, linger

    def _match_other(self, frame: bytes, key: int, raw: int, sids: SidSpace) -> Pending | None:
        """The request a reply whose key ``key`` matches no request of ``sids`` exactly
        answers: one sent to a wildcard address, or the one a relay error names; none
        (counted and logged as late, duplicate or unsolicited: see :func:`log_unmatched`)."""
        pending = sids.pending
        p = match_wildcard(pending, key)
        if p is None and raw >= RELAY_ERROR_BIT and len(frame) >= MIN_RELAY_REPLY_SIZE:
            p = match_relay_error(pending, frame)
        if p is None:
            self._linger_logged = log_unmatched(
                self.transport.description,
                self.stats,
                self.spaces,
                sids,
                key,
                frame,
                raw >= RELAY_ERROR_BIT,
                self._linger_logged,
            )
        return p

    def _held(self, p: Pending, key: int, frame: bytes, sids: SidSpace) -> bool:
        """On a link with a linger, a reply to ``p`` that is a byte-for-byte copy of its
        SID's last reply, or of one of its recent replies (:meth:`SidSpace.copied
        <aiofins.session.sids.SidSpace.copied>`): whether it is held back (see
        :meth:`_hold_copy`; ``p`` put back in the pending table). Without a linger, one of
        a reply the space heard (:attr:`SidSpace.heard
        <aiofins.session.sids.SidSpace.heard>`) to another question: see :meth:`_first_sign`."""
        if not sids.linger:
            return self._first_sign(p, key, sids, frame)
        if sids.answers.get(key) == frame:
            held = self._hold_copy(p, key, sids, frame, sids.asked.get(key))
        elif (older := sids.copied(frame, self.clock())) is not None:
            held = self._hold_copy(p, key, sids, frame, older[1], older[0])
        else:
            return False
        if held:
            sids.pending[key] = p
        return held

    def _unsure(
        self, sids: SidSpace, p: Pending, key: int, frame: bytes, latency: float, now: float
    ) -> None:
        """``frame`` answers ``p``, under ``key``, ``now``, ``latency`` after its send: the
        slowest round trip yet (if ``p`` was sent once: :meth:`SidSpace.slower`), or a
        reply while a copy of a reply was held back (:meth:`_copy_resolved`) or SIDs given
        up on wait for evidence that the destination answers
        (:meth:`SidSpace.answered_after`): :attr:`SidSpace.unsure`."""
        if latency > sids.slowest and p.rtt is not None:
            sids.slower(latency, now)
        if sids.held:
            self._copy_resolved(sids, key, frame, p.frame)
        if sids.given_up:  # an outage's quarantines end now that the destination answers
            sids.answered_after(key, p.sent_at, now)

    def _hold_copy(
        self,
        p: Pending,
        key: int,
        sids: SidSpace,
        frame: bytes,
        old: bytes | None,
        done_at: float | None = None,
    ) -> bool:
        """A reply to ``p`` is a copy, byte for byte, of the reply its SID was last
        answered with (or of an earlier recent one, which came at ``done_at``), to a
        request that sent ``old``: whether it is held back (``p`` waits on; counted as a
        duplicate) rather than answer ``p``. The duplicate
        rule of docs/session.md ("SIDs: quarantine and linger").

        It is that reply's late duplicate, or ``p``'s own reply holding the same bytes;
        nothing in it tells which (a one-byte SID). A request asking the same thing as the
        SID's last reply answered (a poll of values that did not change) takes it; a copy
        of an older reply is held whatever that reply's request asked (the SID carried
        another since: soak seed 60234, a stale value). Else, on a link that has shown
        duplicates (a linger), within :data:`~.sids.HOLD_WINDOW` (1 s) or twice the linger
        of that reply (:meth:`SidSpace.hold
        <aiofins.session.sids.SidSpace.hold>`), it is held, and ``p`` is sent again at once
        (same frame and SID, where the transport sends synchronously; else at its next
        retransmission): its next reply answers it, unless that is a copy of another of
        the SID's replies, held back too (soak seed 220447: copies of the SID's last two
        replies came before its own; the same bytes as one held answer). Only a request that
        may be sent again: one with a plan (retries, or its frame kept on a duplicating
        link: :meth:`_keep_frame`), or a read sent before the link showed a duplicate
        (:func:`~.sids.may_send_again`; soak seed 50267: a read in flight when the link's
        first duplicate was seen took a copy of its SID's last reply)."""
        sent = p.frame
        if p.plan is None and not may_send_again(False, p.mrc, p.src, sent[12:]):
            return False  # (a write without retries: see "What stays exposed")
        if sent == old and done_at is None:
            return False  # the same question as the SID's last: the same answer is no surprise
        if not sids.hold(key, self.clock(), frame, done_at):
            return False
        self.stats.duplicates += 1
        transport = self.transport if p.space is None else p.space.transport
        if transport.fast_send is not None:
            self._send_again(p, transport.fast_send)
        return True

    def _send_again(self, p: Pending, fast_send: Callable[[bytes], None]) -> None:
        """Send ``p`` once more now, same frame and SID (see :meth:`_hold_copy`)."""
        p.rtt = None  # Karn: the reply can no longer be timed
        p.attempts += 1
        self.stats.retries += 1
        try:  # noqa: SIM105 (as in frame_received: no context manager)
            fast_send(p.frame)
        except Exception:  # (its retransmissions or its deadline follow)
            pass

    def _first_sign(self, p: Pending, key: int, sids: SidSpace, frame: bytes) -> bool:
        """The first-sign rule (docs/session.md): on a link that has shown no duplicate (no
        linger), a reply ``frame`` to ``p`` that is, byte for byte, a reply its SID carried
        (:attr:`SidSpace.heard <aiofins.session.sids.SidSpace.heard>`: the frame holds
        its SID key): whether it is held back as a possible copy of that reply (``p`` put
        back in the pending table and sent again at once, same frame and SID). Held when
        ``p`` is a read (:func:`~aiofins.protocol.guard.changes`: it changes nothing, so
        sending it again is harmless) that asked something else than the request that
        reply answered, within :data:`~.sids.HOLD_WINDOW` (1 s) of it, no reply with these
        bytes was held for ``p`` yet, and the transport sends synchronously. ``p`` takes
        its next reply unless that is another such possible copy (held too, each once:
        :meth:`SidSpace.was_held <aiofins.session.sids.SidSpace.was_held>`), and nothing is
        learnt from this sign (:meth:`_copy_resolved`): a false one (two reads of zeros)
        costs one round trip, never a linger, a wait or a loop (the same bytes again
        answer; issue #22, defect 5: soak seed 50040, a SID storm whose link's first
        copies came to SIDs reused by reads, one a read of other words)."""
        sent = p.frame
        found = sids.heard.get(frame)
        if found is None or sent == found[1]:
            return False  # the same question (a poll): it answers
        fast_send = (self.transport if p.space is None else p.space.transport).fast_send
        if (
            sids.was_held(key, frame)  # (held once for p: the same bytes again answer)
            or fast_send is None
            or changes(p.mrc, p.src, sent[12:]) is not None  # (a write: see "What stays exposed")
            or self.clock() - found[0] >= HOLD_WINDOW
        ):
            found[1] = sent  # (it answers p: what these bytes answered, for the next)
            return False
        sids.hold_first(key, frame)
        sids.pending[key] = p
        self._send_again(p, fast_send)
        return True

    def _keep_frame(self, p: Pending, frame: bytes, cap: float | None, now: float) -> None:
        """``p``, idempotent and sent ``now`` without retries (``retries=0``), on a link
        that has shown duplicates: its frame kept in a plan with no retransmission left
        (its deadline and the watcher's handling unchanged), so that the duplicate rule
        may hold back a copy of its SID's last reply and send it once more (see
        :meth:`_hold_copy`): a read is answered by its own reply, not another read's."""
        p.plan = (frame, 0, p.end, cap, p.end - now)

    def _copy_resolved(self, sids: SidSpace, key: int, frame: bytes, sent: bytes) -> None:
        """The request under ``key`` (which sent ``sent``) is answered with ``frame`` after
        a copy of one of its SID's replies was held back (see :meth:`_hold_copy`): if
        ``frame`` differs from the SID's last reply, that copy was a late duplicate of the
        old reply, and teaches the linger; unless ``frame`` is, byte for byte, an older
        reply of the SID to the same question as ``sent`` (a poll whose value did not
        change: the copy held back may have been its own reply; nothing learnt)."""
        lateness = sids.unhold(key)
        if lateness == FIRST_SIGN:  # (see _first_sign: nothing learnt)
            if frame not in sids.heard:  # not the bytes held back: those were a copy
                self.stats.duplicates += 1
            return
        if (older := sids.copied(frame, self.clock())) is not None and older[1] == sent:
            return
        if lateness is not None and frame != sids.answers.get(key):
            grew = sids.learn(lateness, self.clock())
            self._linger_logged = log_duplicate(
                self.transport.description, self.spaces, sids, key, grew, self._linger_logged
            )

    def _misdirected(self, frame: bytes, to: int, sids: SidSpace) -> bool:
        """Whether a reply received on SID space ``sids`` is for another of our addresses
        (its ``DNA DA1 DA2``, in ``to``, is not the space's source): it never matches this
        space's requests. Counted (``stats.misdirected``) and handed to our space that
        owns the address, if any (an Ethernet unit with an IP address table or static
        conversion sends every reply to one port, whichever socket the command came from),
        else dropped. False (the space's own) for network 0 against a network number, and
        while the space's address is not known."""
        to &= ADDRESS_MASK
        if sids.ours < 0 or same_address(to, sids.ours):
            return False
        self.stats.misdirected += 1
        owner: ExtraSpace | None = None
        if same_address(to, self.sids.ours):
            found = True
        else:
            owner = next((s for s in self.spaces.extra if same_address(to, s.sids.ours)), None)
            found = owner is not None
        if logger.isEnabledFor(_DEBUG):
            where = self.transport.description
            logger.debug(
                "%s: a reply to %s came to the socket of %s: %s",
                where,
                FinsAddress(*key_address(to << 8)),
                FinsAddress(*key_address(sids.ours << 8)),
                "handed to its SID space" if found else "none of ours, dropped",
                extra={"endpoint": where},
            )
        if found:
            self.frame_received(frame, None, owner)
        return True

    def log_frames_now(self) -> None:
        """Ask logging whether the frames sent and received are logged (DEBUG) from now
        on: once per call (:meth:`request` does it inline) and per burst of a batch, not
        per frame; a change of level shows from the next call or burst."""
        self._log_frames = logger.isEnabledFor(_DEBUG)

    def emit(self, handlers: list[Any], event: Callable[..., Any], p: Pending, *more: Any) -> None:
        """Hand one request event (:class:`RequestSent`, :class:`ResponseReceived`,
        :class:`RequestRetried`, :class:`RequestTimedOut`) about ``p`` to ``handlers``: the
        endpoint, destination, SID and command first, then ``more``."""
        assert self._hooks is not None
        key = p.key
        self._hooks.emit(
            handlers,
            event(
                self.transport.description,
                FinsAddress(*key_address(key)),
                key & 0xFF,
                (p.mrc << 8) | p.src,
                *more,
            ),
        )

    def frame_dropped(self, reason: str) -> None:
        self.stats.malformed += 1
        if logger.isEnabledFor(_DEBUG):
            where = self.transport.description
            logger.debug("%s: frame dropped: %s", where, reason, extra={"endpoint": where})

    def connection_lost(self, exc: BaseException | None) -> None:
        self._link.connection_lost(exc)

    def fail_all(self, exc: BaseException) -> None:
        """Fail every request in flight on the session's own transport with ``exc`` (the
        link failed or the session closes), their SIDs quarantined."""
        self.sids.fail_all(exc, self.quarantine_until)
        if not self.spaces.extra:  # (else their requests' deadlines stay)
            self._deadlines.clear()

    def _fail_space(self, space: ExtraSpace, exc: BaseException) -> None:
        """``space``'s link failed or it closes: its requests fail, their SIDs quarantined
        (its transport is closed next: a late reply can no longer reach anyone)."""
        space.sids.fail_all(exc, self.quarantine_until)

    # ----------------------------------------------------------------- deadlines

    def quarantine_until(self, now: float, timeout: float) -> float:
        """When a SID given up on ``now`` (its request timed out or was cancelled) may be used
        again, unless its late reply comes first: ``max(quarantine_factor x timeout,
        min_quarantine)`` from now."""
        return now + max(self.quarantine_factor * timeout, self.min_quarantine)

    # ----------------------------------------------------------------- the hot path
    # One request's steps, used by request() and by request_many()'s batches (batch.py):
    # dest_state() -> sids.take() -> build the frame -> start() -> send -> frame_received()
    # -> response() / busy_pause() / end_code_failure(); or abandon() / _expire().

    def dest_state(self, dest: FinsAddress) -> DestState:
        """The header prefix, SID cursor, slots and round-trip estimate of ``dest``."""
        if dest is self._last_dest:
            return self._last_state  # type: ignore[no-any-return]
        state = self._dests.get(dest)
        if state is None:
            if self._shared_slots:
                slots = self._slots.get(None)
                if slots is None:
                    slots = self._slots[None] = SlotQueue(self.max_in_flight)
            else:
                slots = self._slots[dest] = SlotQueue(self.max_in_flight)
            state = self._dests[dest] = DestState(dest, self._prefix(dest), slots)
            self.sids.routed = len(self._dests) > 1
        self._last_dest, self._last_state = dest, state
        return state

    def _prefix(self, dest: FinsAddress) -> bytes:
        """ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2: the header before the SID."""
        return self._prefix_from(dest, self.source)

    def _prefix_from(self, dest: FinsAddress, s: FinsAddress) -> bytes:
        """The header before the SID from source ``s`` (an extra SID space's) to ``dest``."""
        return header_prefix(
            self.gct, (dest.network, dest.node, dest.unit), (s.network, s.node, s.unit)
        )

    def start(
        self,
        p: Pending,
        state: DestState,
        mrc: int,
        src: int,
        params: bytes,
        retries: int,
        now: float,
        end: float,
        cap: float | None,
        space: ExtraSpace | None = None,
    ) -> bytes | None:
        """``p``, command ``mrc src params`` to ``state``'s destination, on the books: a free
        SID, the frame (returned, to send), every field of ``p``, its plan and first deadline
        (docs/session.md), watcher, hooks, log; ``None`` if no SID is free (nothing done)."""
        if space is None:
            sids, mine = self.sids, state
        else:  # its own SIDs and header; the destination's slots and round-trip estimate
            sids, mine = space.sids, space.dest_state(state)
        pending = sids.pending
        sid = mine.cursor  # SidSpace.take(), inlined: a change to one is a change to both
        key = mine.keys[sid]  # (the same int object for the SID every time: DestState.keys)
        if (
            key in pending
            or key in sids.quarantine
            or ((lingering := sids.lingering) and lingering.get(key, 0.0) > now)
            or (sids.routed and sids.sid_taken(key))
        ):
            if (found := sids.allocate(mine)) is None:
                return None
            key, sid = found, found & 0xFF
        else:
            mine.cursor = sid + 1 if sid < 255 else 0
        frame = pack_head(mine.prefix, sid, mrc, src) + params  # (bad params raise here)
        p.key, p.mrc, p.src = key, mrc, src  # (three at most: no tuple made)
        p.rtt, p.space, p.frame = state, space, frame
        p.done = p.abandoned = False
        p.reply, p.attempts, p.end = None, 1, end
        if retries:
            wait = state.rto or (end - now) / ((2 << retries) - 1)
            if cap is not None and wait > cap:
                wait = cap
            p.plan = (frame, retries, end, cap, wait)
            if (deadline := now + wait) > end:
                deadline = end
        else:
            p.plan = None
            deadline = now + cap if cap is not None and now + cap < end else end
        p.deadline, p.sent_at = deadline, now
        if not (fifo := self._fifo) or deadline >= fifo[-1].deadline:
            fifo.append(p)
        else:
            self._deadlines.add(p)
        if deadline < self._watcher.at:
            self._watcher.arm(deadline, now)
        if self._log_frames or self._hooks is not None:
            self._sent_told(p, frame)
        pending[key] = p
        return frame

    def start_burst(
        self,
        ps: list[Pending],
        commands: list[tuple[int, int, bytes]],
        state: DestState,
        retries: int,
        now: float,
        end: float,
    ) -> list[bytes]:
        """:meth:`start` each of ``ps`` (command ``commands[i]`` for ``ps[i]``) to
        ``state``'s destination on the session's own transport, all sent ``now`` with the
        call's deadline ``end``, no per-attempt cap (a batch's burst): their frames, in
        order; fewer when one finds no free SID (it and those after it not registered).
        The first goes through :meth:`start`; the others share its
        send time, deadline and plan, so what :meth:`start` decided for it is copied,
        not decided again: each takes a SID (:meth:`SidSpace.take`), gets its frame and
        fields, and goes where the first went in the deadlines (the watcher is armed for
        that deadline already); the hooks and the log told as for the first."""
        frames: list[bytes] = []
        if not ps:
            return frames
        first = ps[0]
        mrc, src, params = commands[0]
        frame = self.start(first, state, mrc, src, params, retries, now, end, None)
        if frame is None:
            return frames
        frames.append(frame)
        sids = self.sids
        pending, prefix = sids.pending, state.prefix
        deadline, plan = first.deadline, first.plan
        wait = plan[4] if isinstance(plan, tuple) else 0.0
        fifo = self._fifo
        in_order = bool(fifo) and fifo[-1] is first  # (else it went to the heap: so do these)
        told = self._log_frames or self._hooks is not None
        for i in range(1, len(ps)):
            key = sids.take(state, now)  # (methods called, not bound: mypyc calls them natively)
            if key is None:
                break
            p = ps[i]
            mrc, src, params = commands[i]
            frame = pack_head(prefix, key & 0xFF, mrc, src) + params
            p.key, p.mrc, p.src = key, mrc, src
            p.rtt, p.space = state, None
            p.done = p.abandoned = False
            p.reply = None
            p.frame = frame
            p.attempts = 1
            p.end = end
            p.deadline = deadline
            p.sent_at = now
            p.plan = (frame, retries, end, None, wait) if plan is not None else None
            if in_order:
                fifo.append(p)
            else:
                self._deadlines.add(p)
            if told:
                self._sent_told(p, frame)
            pending[key] = p
            frames.append(frame)
        return frames

    def _sent_told(self, p: Pending, frame: bytes) -> None:
        """The hooks (:class:`RequestSent`) and the DEBUG log told that ``p`` is sent."""
        hooks = self._hooks
        if hooks is not None and hooks.request_sent:
            self.emit(hooks.request_sent, RequestSent, p)
        if self._log_frames:
            log_frame(self.transport.description, "sent", frame)

    def abandon(self, p: Pending, timeout: float, timed_out: bool = False) -> None:
        """Give up on ``p`` before its reply (cancelled, or its send failed; ``timed_out``:
        the send timed out): out of the table, its SID quarantined, counted."""
        if p.done:
            return
        (self.sids if p.space is None else p.space.sids).abandon(
            p, self.quarantine_until(self.clock(), timeout)
        )
        if timed_out:
            self.stats.timeouts += 1
        else:
            self.stats.cancelled += 1

    def completed(self, end_code: int) -> bool:
        """Whether a reply's end code (``end_code``, as the receive path read it:
        :attr:`Pending.end_code`) is a normal completion (counted; CPU error flags
        logged); if not, see :meth:`busy_pause` and :meth:`end_code_failure`."""
        if end_code & ERROR_BITS:
            return False
        self.stats.completed += 1
        if end_code:
            where = self.transport.description
            self._flags_logged = cpu_flags_seen(where, end_code, self._flags_logged)
        return True

    def response(self, frame: bytes, end_code: int) -> Response | None:
        """The :class:`Response` a reply carries if its end code is a normal completion
        (see :meth:`completed`), else ``None``."""
        if not self.completed(end_code):
            return None
        return response_of(frame)

    def busy_pause(self, frame: bytes, busy: int) -> float | None:
        """For a reply with an error end code: the pause before sending the command again
        if the PLC was too busy to execute it (2604/2605) and ``busy`` retries of it were
        made so far, fewer than ``busy_retries``; ``None`` otherwise."""
        raw = (frame[12] << 8) | frame[13]
        if raw & CPU_ERROR_FLAGS:
            where = self.transport.description
            self._flags_logged = cpu_flags_seen(where, raw, self._flags_logged)
        if (raw & END_CODE_MASK) in BUSY_CODES and busy < self.busy_retries:
            return self.busy_backoff * (1 << busy)
        return None

    def end_code_failure(self, frame: bytes, mrc: int, src: int) -> FinsError:
        """The error a reply's end code means (counted)."""
        self.stats.end_code_errors += 1
        return end_code_error(frame, mrc, src)

    @property
    def loop(self) -> Any:
        """The running asyncio event loop (``None`` under other backends)."""
        return self._loop

    @property
    def on_asyncio(self) -> bool:
        """Whether the session runs under asyncio (set on entry)."""
        return self._asyncio

    async def ensure_open(self, timeout: float | None = None) -> None:
        """Open the link if it is closed, waiting at most ``timeout`` (see :class:`Link`)."""
        await self._link.ensure_open(timeout)

    # ----------------------------------------------------------------- the request path
    # A request is begin() (checks, slot, SID, register, send, read-after-send), one await
    # of its Pending, and finish() (end code, counters, breaker, busy retry decision) or
    # failure(): plain methods, no coroutine of their own. call() is the same steps with
    # the waits (link, breaker probe, slot, SID, an awaited send, busy pauses) for a
    # request begin() cannot start at once. request_many()'s batches (batch.py) use
    # start() / completed() / busy_pause() / end_code_failure() for each command.

    def begin(
        self,
        mrc: int,
        src: int,
        params: bytes = b"",
        dest: FinsAddress | None = None,
        timeout: float | None = None,
        idempotent: bool = False,
        retries: int | None = None,
        cap: float | None = None,
        in_call: bool = False,
        now: float | None = None,
        pending: Pending | None = None,
    ) -> Pending | None:
        """Check, take a slot and a SID, register, send, read right after: the :class:`Pending`
        (then ``await p``, :meth:`finish` or :meth:`failure`), or ``None`` (nothing done) to
        wait in :meth:`call`. Options as :meth:`request`'s (``cap``, ``pending``: see docs)."""
        if dest is None:
            dest = self.dest
        if timeout is None and retries is None and cap is None:  # (checked when set)
            timeout = self.timeout
            retries = self.retries if idempotent else 0
            cap = self.attempt_timeout
        else:
            timeout, retries, cap = self._call_options(timeout, idempotent, retries, cap)
        if (mrc | src) >> 8 or len(params) > MAX_PARAMETER_SIZE:  # (a negative one too)
            check_call(mrc, src, params, timeout, retries, cap)  # raises what is wrong
        if self._turn_due or (self._breaker.state is not _CLOSED_BREAKER and not in_call):
            return None
        send = (transport := self.transport).fast_send
        state = self._last_state if dest is self._last_dest else self.dest_state(dest)
        slots = state.slots
        if send is None or slots.in_flight >= slots.limit or slots.waiters:
            return None
        slots.in_flight += 1
        if now is None:
            clock = self.clock  # (as in frame_received)
            now = clock()
        log = _ENABLED.get(_DEBUG)  # (log_frames_now(), inlined)
        self._log_frames = logger.isEnabledFor(_DEBUG) if log is None else log
        asyncio_made = pending is None and self._asyncio
        p = pending or (AsyncioPending() if asyncio_made else self._other_pending())
        p.slots = slots
        p.fut = None  # (under asyncio made after the send if it is not answered by then)
        frame = self.start(p, state, mrc, src, params, retries, now, now + timeout, cap)
        if frame is None:  # no SID free at once: call() waits for one
            self._slot_back(p)
            return None
        if not retries and self.sids.linger and may_send_again(idempotent, mrc, src, params):
            p.plan = (frame, 0, p.end, cap, p.end - now)  # (see _keep_frame)
        try:
            send(frame)
        except Exception as exc:
            return self._unsent(p, exc, timeout, pending)
        if (poll := transport.poll_now) is not None and pending is None:
            self._read_after_send(poll, p)
        if asyncio_made and not p.done:  # not answered (nor failed) yet: a future to wait on
            new_future = self._new_future  # (a callable attribute: see frame_received)
            p.fut = new_future()  # (p.fut tested here: None to mypyc)
        return p

    def _unsent(
        self, p: Pending, exc: Exception, timeout: float, pending: Pending | None
    ) -> Pending | None:
        """:meth:`begin`'s send of ``p`` raised ``exc``: ``p`` given up (its SID
        quarantined, counted) and failed with ``exc``, which its caller's await raises
        (then :meth:`failure`: the slot back, the breaker told); a caller's own record
        (``pending``) is not failed but its slot given back, and ``None`` returned."""
        self.abandon(p, timeout, isinstance(exc, FinsTimeout))
        if pending is not None:
            self._slot_back(p)
            return None
        p.fail(exc)
        return p

    def _call_options(
        self, timeout: float | None, idempotent: bool, retries: int | None, cap: float | None
    ) -> tuple[float, int, float | None]:
        """A call's ``timeout``, ``retries`` and ``cap`` (``attempt_timeout``), the
        session's where not given; :class:`CommandError` for one out of its range."""
        if timeout is None:
            timeout = self.timeout
        if retries is None:
            retries = self.retries if idempotent else 0
        if cap is None:
            cap = self.attempt_timeout
        if not (timeout > 0.0 and retries >= 0 and (cap is None or cap > 0.0)):
            check_call(0, 0, b"", timeout, retries, cap)  # raises what is wrong
        return timeout, retries, cap

    def _pending_made(self) -> Pending:
        """A new request's :class:`Pending` (its fields set by :meth:`start`): on a bare
        asyncio future under asyncio, else the session's other kind (an anyio event's
        under trio, a :class:`HeldPending` without an event loop)."""
        if self._asyncio:
            p: Pending = AsyncioPending()
            p.fut = self._new_future()
            return p
        p = self._other_pending()
        return p

    def _slot_back(self, p: Pending) -> None:
        """Give back the slot ``p`` holds, if the watcher has not already (to the first
        waiter of the destination, if any)."""
        slots = p.slots
        if slots is not None:
            p.slots = None
            if slots.waiters:
                slots.release()
            else:
                slots.in_flight -= 1

    def finish(self, p: Pending, frame: bytes, busy: int = 0) -> bool:
        """``frame`` answered ``p`` (``busy``: the busy replies its call got before):
        its slot given back; True for a normal completion (counted, CPU error flags
        logged, the breaker told: the data is ``frame[14:]``); False when the PLC was too
        busy to execute it (2604/2605) and a retry fits before the call's deadline:
        :meth:`call` with ``after=p`` sends it again after :meth:`busy_wait`. Any other
        end code raises its error (the PLC answered: the breaker closes). (Its common case
        is inlined in :meth:`request`: a change to one is a change to both.)"""
        slots = p.slots  # (_slot_back() and completed(), inlined: once per request)
        if slots is not None:
            p.slots = None
            if slots.waiters:
                slots.release()
            else:
                slots.in_flight -= 1
        end_code = p.end_code
        if not end_code & ERROR_BITS:
            self.stats.completed += 1
            if end_code:
                where = self.transport.description
                self._flags_logged = cpu_flags_seen(where, end_code, self._flags_logged)
            if self._breaker.failures:
                call_answered(self._breaker, self.transport.description)
            return True
        return self._not_completed(p, frame, busy)

    def _not_completed(self, p: Pending, frame: bytes, busy: int) -> bool:
        """:meth:`finish` of a reply whose end code is not a normal completion: False for
        a busy one with a retry that fits before the call's deadline, else raised."""
        pause = self.busy_pause(frame, busy)
        if pause is not None and pause < p.end - self.clock():
            self.stats.busy_retries += 1
            return False
        if self._breaker.failures:
            call_answered(self._breaker, self.transport.description)
        raise self.end_code_failure(frame, p.mrc, p.src)

    def busy_wait(self, busy: int) -> float:
        """The pause before sending a command again after its ``busy + 1``-th busy reply."""
        return self.busy_backoff * (1 << busy)

    def failure(
        self,
        p: Pending | None,
        exc: BaseException,
        timeout: float | None = None,
        in_call: bool = False,
    ) -> BaseException:
        """A call ends with ``exc`` (``p``: its latest request, if it got that far): ``p``
        given up if unanswered (SID quarantined, counted), its slot given back; the breaker
        told (unless ``in_call``: the enclosing call tells it); returns the error to raise
        (a request given up after its deadline: a :class:`FinsTimeout` saying after how
        many attempts, with what to check)."""
        if timeout is None:
            timeout = self.timeout
        if p is not None:
            self.abandon(p, timeout, isinstance(exc, FinsTimeout))
            self._slot_back(p)
        error = exc
        if isinstance(exc, Expired):
            assert p is not None
            error = no_response(
                self.transport,
                self.source,
                FinsAddress(*key_address(p.key)),
                p.mrc,
                p.src,
                timeout,
                p.attempts,
            )
        if not in_call:
            call_ended(self._breaker, error, timeout, self.transport.description, self.clock())
        return error

    async def failed(
        self,
        p: Pending | None,
        exc: BaseException,
        timeout: float | None = None,
        in_call: bool = False,
    ) -> NoReturn:
        """:meth:`failure`, raised: a lost link after a turn of the event loop (see
        :func:`raise_after_a_turn`)."""
        error = self.failure(p, exc, timeout, in_call)
        if error is not exc:
            raise error from None
        if isinstance(error, ConnectionLost):
            await raise_after_a_turn(error)
        raise error

    async def call(
        self,
        mrc: int,
        src: int,
        params: bytes = b"",
        dest: FinsAddress | None = None,
        timeout: float | None = None,
        idempotent: bool = False,
        retries: int | None = None,
        cap: float | None = None,
        in_call: bool = False,
        after: Pending | None = None,
    ) -> bytes:
        """The request path with its waits: the steps of :meth:`begin`, the await and
        :meth:`finish`, for a request that has to wait for the event loop's fair turn,
        the breaker's probe, the link, a slot, a SID or an awaited send, and again after
        each busy reply (``after``: the request whose reply said busy, once :meth:`finish`
        returned False for it). Returns the reply frame of a normal completion; raises as
        :meth:`request`."""
        if dest is None:
            dest = self.dest
        timeout, retries, cap = self._call_options(timeout, idempotent, retries, cap)
        check_command(mrc, src, params)
        if after is None:
            end = self.clock() + timeout
            if self._breaker.failures and not in_call:  # (none: the breaker is closed)
                await self._admitted(dest)  # (turned away: the breaker is told nothing)
        else:
            end = after.end
        p = after
        try:
            if after is not None:
                await anyio.sleep(self.busy_wait(0))
            busy = 0 if after is None else 1
            while True:
                p = await self._sent(mrc, src, params, dest, timeout, retries, cap, end, idempotent)
                frame = await (p.fut or p.wait())
                if self.finish(p, frame, busy):
                    return frame
                await anyio.sleep(self.busy_wait(busy))
                busy += 1
        except BaseException as exc:
            await self.failed(p, exc, timeout, in_call)

    async def _admitted(self, dest: FinsAddress) -> None:
        """Before a call of :meth:`call` starts while the breaker counts failures: its
        leave (the call may be the probe; :class:`CircuitOpen` otherwise). A call turned
        away tells the breaker nothing (it would end the probe's turn)."""
        where = self.transport.description
        await admit_call(self._breaker, self.stats, dest, where, self.clock())

    async def _sent(
        self,
        mrc: int,
        src: int,
        params: bytes,
        dest: FinsAddress,
        timeout: float,
        retries: int,
        cap: float | None,
        end: float,
        idempotent: bool = False,
    ) -> Pending:
        """One request of :meth:`call` on the wire, waiting as it must until ``end``: for
        the link, a slot of ``dest``, a SID (see :func:`start_when_free`), the send; then
        the transport read right after, or the event loop's fair turn if it is due (see
        :meth:`_read_after_send`)."""
        transport = self.transport
        if transport.fast_send is None and not transport.is_open:
            await self._link.ensure_open(end - self.clock(), call_timeout=timeout)
        self._log_frames = logger.isEnabledFor(_DEBUG)
        state = self.dest_state(dest)
        slots = state.slots
        if not slots.try_acquire():
            await slots.acquire(max(end - self.clock(), 0.0), f"{dest}")
        p = self._pending_made()
        p.slots = slots
        try:
            now = self.clock()
            frame = self.start(p, state, mrc, src, params, retries, now, end, cap)
            if frame is None:  # no free SID at hand: wait for one (none taken if not)
                command = (mrc, src, params)
                frame, transport, now = await start_when_free(
                    self, p, state, command, retries, end, cap, timeout
                )
        except BaseException:
            self._slot_back(p)
            raise
        if not retries and self.sids.linger and may_send_again(idempotent, mrc, src, params):
            self._keep_frame(p, frame, cap, now)
        try:
            if (fast_send := transport.fast_send) is not None:
                fast_send(frame)
            else:
                await transport.send(frame, end - now)
        except BaseException as exc:  # given up (SID quarantined), the slot given back
            self.abandon(p, timeout, isinstance(exc, FinsTimeout))
            self._slot_back(p)
            p.unawaited()  # (the link may have failed it meanwhile: exc is raised instead)
            raise
        if self._turn_due:  # (asyncio only)
            self._turn_due = False
            await asyncio.sleep(0)  # a bare yield, after the send: see _read_after_send
        elif (poll := transport.poll_now) is not None:
            self._read_after_send(poll, p)
        return p

    # Session.request is begin(), one await and finish(), with the common case of each
    # written out: a call with the session's destination and options, the breaker closed,
    # a slot free and a synchronous send; a normal completion with no flags, no waiter for
    # the slot and no breaker to tell. That is two Python calls less per request (issue
    # #22's bound on instructions per request: benchmarks/README.md) on the path nearly
    # every request of a sequential caller or of tasks sharing a session takes. Any other
    # call goes through begin(), finish() and call(). A change to begin() or finish() is a
    # change to the lines written out here (tests/session/test_structure.py allows this
    # def its length for that reason).

    async def request(
        self,
        mrc: int,
        src: int,
        params: bytes = b"",
        *,
        dest: FinsAddress | None = None,
        timeout: float | None = None,
        idempotent: bool = False,
        retries: int | None = None,
        attempt_timeout: float | None = None,
        _in_call: bool = False,
    ) -> Response:
        """Send one command and return its normal-completion response.

        ``timeout`` bounds the whole call (link, slot, SID, every transmission, reply);
        ``attempt_timeout`` caps each transmission's wait. Raises the :class:`EndCodeError`
        subclass for the end code (:class:`RelayError` for bit 15), :class:`FinsTimeout`
        when no reply came in time (saying after how many attempts), :class:`ConnectionLost`
        when the link failed or the session closed, :class:`CircuitOpen` while the
        destination's breaker is open. (``_in_call``, internal: a command of a call that
        passed the circuit breaker itself, :meth:`request_many`'s portable path.)
        """
        state, p = self._last_state, None  # (begin()'s common case, written out: see above)
        if (
            (dest is None and timeout is None and retries is None and attempt_timeout is None)
            and not (self._turn_due or len(params) > MAX_PARAMETER_SIZE)
            and (self._breaker.state is _CLOSED_BREAKER or _in_call)
            and self.dest is self._last_dest
            and (send := (transport := self.transport).fast_send) is not None
            and (slots := state.slots).in_flight < slots.limit
            and not slots.waiters
        ):
            slots.in_flight += 1
            clock, log = self.clock, _ENABLED.get(_DEBUG)  # (clock: as in frame_received)
            self._log_frames = logger.isEnabledFor(_DEBUG) if log is None else log
            now, cap, asyncio_made = clock(), self.attempt_timeout, self._asyncio
            p = AsyncioPending() if asyncio_made else self._other_pending()
            p.slots, p.fut, retries = slots, None, self.retries if idempotent else 0
            try:  # (begin's command check, made by the frame's packing: no cost when good)
                sent = self.start(
                    p, state, mrc, src, params, retries, now, now + self.timeout, cap, None
                )
            except StructError:  # a command code not an int in 0..255: said which
                self._slot_back(p)
                check_call(mrc, src, params, self.timeout, retries, cap)
                raise
            if sent is None:  # no SID free at once: call() waits for one
                self._slot_back(p)
                p = None
            else:
                if (
                    not retries
                    and self.sids.linger
                    and may_send_again(idempotent, mrc, src, params)
                ):
                    p.plan = (sent, 0, p.end, cap, p.end - now)  # (see _keep_frame)
                try:
                    send(sent)
                except Exception as exc:
                    p = self._unsent(p, exc, self.timeout, None)
                else:
                    if (poll := transport.poll_now) is not None:
                        self._read_after_send(poll, p)
                    if asyncio_made and not p.done:  # (a future to wait on: see begin)
                        new_future = self._new_future
                        p.fut = new_future()
        else:
            p = self.begin(
                mrc, src, params, dest, timeout, idempotent, retries, attempt_timeout, _in_call
            )
        if p is not None:
            try:
                frame = p.reply or await (p.fut or p.wait())  # (answered at once: no wait)
            except BaseException as exc:
                await self.failed(p, exc, timeout, _in_call)
            slots = p.slots  # (finish()'s common case, written out: see above)
            if slots is not None and not (slots.waiters or p.end_code or self._breaker.failures):
                p.slots = None
                slots.in_flight -= 1
                self.stats.completed += 1
                response: Response = _new(Response)  # (response_of(), inlined: end code 0000)
                _set_end_code(response, _NORMAL)
                _set_data(response, frame[14:])
                _set_frame(response, frame)
                return response
        if p is None or not self.finish(p, frame):  # a wait first, or busy: a pause
            frame = await self.call(
                mrc, src, params, dest, timeout, idempotent, retries, attempt_timeout, _in_call, p
            )
        return response_of(frame)

    def _read_after_send(self, poll: Callable[[], None], p: Pending) -> None:
        """Read the transport right after sending ``p`` if it is alone in flight (``poll``:
        the transport's ``poll_now``).

        A peer on the same core often answers during the send itself: the request then
        completes without an event-loop pass. Adaptive: after one miss the next request tries
        again (the peer was merely late); after misses in a row (the peer answers later, e.g.
        from another core) the next 1, 2, 4 ... 64 requests skip the attempt, so it costs next
        to nothing where it never helps. Only for a sequential caller: a request sent while
        others are in flight makes the next :data:`_POLL_MAX_BACKOFF` skip it, as with
        concurrent callers the one whose request is momentarily alone would otherwise run
        its round trips one after another while the others, woken, wait to send theirs
        together (50 tasks over FINS/TCP on one core fell from 55-87k to 29k req/s). Fair:
        after :data:`_POLL_STREAK` requests
        completed this way in a row, the next request yields to the event loop after its
        send instead (:meth:`begin` leaves that request to :meth:`call`), so other tasks,
        timers and cancellation run. The yield is a bare one, not a
        wait for that request's reply: under uvloop a reply already queued is read before the
        pass that runs anyio's cancellation retry, which then finds the task about to wake
        with a result and leaves it alone, turn after turn. (With many in flight the replies
        are read in one drain per loop pass instead, which is cheaper and keeps tasks fair.)
        Under trio the wait for a reply already there is a checkpoint all the same, so the
        request still yields; what the read saves is the reader task's wake-up.
        """
        if len(self._pending) != 1:  # concurrent callers
            self._poll_skip = _POLL_MAX_BACKOFF
            return
        if self._poll_skip:
            self._poll_skip -= 1
            self._poll_streak = 0
            return
        poll()
        if p.done:  # answered
            self._poll_backoff = 0
            streak = self._poll_streak + 1
            if streak >= _POLL_STREAK and self._asyncio:
                streak = 0
                self._turn_due = True
            self._poll_streak = streak
        else:
            backoff = self._poll_backoff
            self._poll_skip = backoff
            self._poll_backoff = min(2 * backoff or 1, _POLL_MAX_BACKOFF)
            self._poll_streak = 0

    async def request_many(
        self,
        requests: Sequence[tuple[int, int, bytes]],
        *,
        dest: FinsAddress | None = None,
        timeout: float | None = None,
        idempotent: bool = False,
        retries: int | None = None,
        window: int | None = None,
        on_response: Callable[[int, Response], object] | None = None,
        on_frame: Callable[[int, bytes], object] | None = None,
    ) -> list[Response]:
        """Send many commands ``(mrc, src, params)`` pipelined; their responses in order.

        Up to ``window`` (default and at most: the destination's in-flight cap) are on the
        wire at once. Under asyncio the replies are handled in the receive callback, which
        sends the next command, so the caller wakes once for the whole batch. Each command
        keeps the guarantees of :meth:`request` (``timeout`` bounds each command's exchange,
        retransmission, busy end codes); the first error is raised after the rest are
        abandoned (SIDs quarantined). ``on_response(index, response)`` is called as each
        command's normal response arrives, in the order they arrive (under asyncio from
        the receive callback: keep it short); an exception it raises ends the batch the
        same way and is raised to the caller. ``on_frame(index, frame)`` instead hands
        it each normal reply frame itself (its data: ``frame[14:]``), as ``on_response``
        would be called, and no :class:`Response` is made: the list returned is empty
        (for a caller that decodes the frames, as ``Client.read_array`` does).
        """
        breaker = self._breaker
        if breaker.state is not _CLOSED_BREAKER:
            await admit_call(
                breaker, self.stats, dest or self.dest, self.transport.description, self.clock()
            )
        try:
            responses = await request_many(
                self,
                requests,
                dest=dest,
                timeout=timeout,
                idempotent=idempotent,
                retries=retries,
                window=window,
                on_response=on_response,
                on_frame=on_frame,
            )
        except BaseException as exc:
            self.tell_breaker(exc, self.timeout if timeout is None else timeout)
            raise
        if breaker.failures:
            call_answered(breaker, self.transport.description)
        return responses

    def tell_breaker(self, error: BaseException | None, timeout: float) -> None:
        """How a call that did not go through :meth:`request` ended (``None``: answered;
        an end code: the PLC answered all the same; else the call's failure after
        ``timeout``), for the destination's circuit breaker."""
        breaker = self._breaker
        if error is None:
            if breaker.failures:
                call_answered(breaker, self.transport.description)
        elif isinstance(error, EndCodeError):
            call_answered(breaker, self.transport.description)
        else:
            call_ended(breaker, error, timeout, self.transport.description, self.clock())

    def spare_sid(self, state: DestState, now: float) -> tuple[int, ExtraSpace] | None:
        """For a batch that found no free SID of the transport's own: one of an open extra
        space, and the space. A batch cannot wait for a space to open: if none has a free
        SID, one is opened in the background (if allowed) for its next try."""
        spaces = self.spaces
        got = spaces.take(state, now) or spaces.allocate(state)
        if got is None and spaces.may_open(now):
            # (from the deadline watcher's task: a batch runs in receive callbacks, where
            # no task can be started)
            self._watcher.from_task(lambda: spaces.open_soon(self.source, self.nodes_in_use()))
        return got

    def requests_in_flight(self) -> list[Pending]:
        """Every request in flight, on every SID space."""
        out = list(self.sids.pending.values())
        for space in self.spaces.extra:
            out.extend(space.sids.pending.values())
        return out

    def nodes_in_use(self) -> set[int]:
        """Nodes an extra space's socket may not take as its source: ours and those of
        the destinations we address."""
        return {self.source.node, *(d.node for d in self._dests)}
