"""More SID spaces for one session, instead of reusing a SID early.

One socket (UDP) or connection (FINS/TCP) has 256 SIDs per destination, and a SID is not
reused while a reply to its last use could still arrive (see :mod:`.sids`). At a given
linger ``L`` one space carries at most ``256 / L`` requests per second to a destination.
When a request finds every SID of the session's own space taken, the session opens another
space, :class:`ExtraSpace`: another socket from another local port with a source node (SA1)
of its own (a UDP peer replies to the last port it saw for a node; the node comes from
:data:`~aiofins.session.nodes.SOURCE_NODES`, so no other session's socket uses it), or
another FINS/TCP connection, whose node the PLC assigns. A new socket or connection starts
with a clean SID space: nothing late can reach it. Replies are matched per space.

At most ``limit`` spaces in all (the session's own included: ``max_sid_spaces``). A space that
carried no request for :attr:`SidSpaces.idle_after` seconds is closed; a UDP space's node
then cools until no late reply to it can come. Opening a space is logged (INFO) and counted
(``stats.sid_spaces_opened``), a failed opening too (WARNING, ``stats.sid_space_failures``,
none tried again for :data:`RETRY_AFTER`); every move of a space is a
:class:`~aiofins.hooks.SidSpaceChanged` hook event. A request that finds every SID of
every space taken at the cap waits for one (``stats.sid_exhausted``, see the session).
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Callable
from time import monotonic
from typing import Protocol

import anyio

from ..hooks import EventHooks, SidSpaceChanged
from ..protocol.errors import ConnectionLost
from ..protocol.frames import address_bits
from ..protocol.header import FinsAddress
from ..transport.base import Transport
from .background import Background
from .clock import Clock
from .messages import no_free_sid
from .nodes import SOURCE_NODES
from .response import SessionStats
from .sids import SHORTAGE_EPISODE, SID_WAIT, SidSpace
from .slots import DestState, EventPending, Pending

logger = logging.getLogger("aiofins.session")

#: Seconds without a request after which an extra space is closed.
IDLE_AFTER = 10.0
#: Seconds after a failed opening before another space is tried.
RETRY_AFTER = 1.0


class SpaceState(enum.Enum):
    """Where an extra SID space stands. :meth:`SidSpaces.move` makes every transition."""

    #: Its socket or connection is being opened; requests that need it wait for it, each at
    #: most its own deadline.
    OPENING = "opening"
    #: Open: it carries requests when the spaces before it have no free SID.
    OPEN = "open"
    #: Being closed (idle, its link lost, or the session closing): it takes no request.
    CLOSING = "closing"
    #: Closed; a UDP space's source node cools until no late reply can come to it.
    CLOSED = "closed"


#: The moves a space may make; anything else is a bug (``AssertionError``).
SPACE_TRANSITIONS: dict[SpaceState, frozenset[SpaceState]] = {
    SpaceState.OPENING: frozenset({SpaceState.OPEN, SpaceState.CLOSING}),
    SpaceState.OPEN: frozenset({SpaceState.CLOSING}),
    SpaceState.CLOSING: frozenset({SpaceState.CLOSED}),
    SpaceState.CLOSED: frozenset(),
}


class ExtraSpace:
    """One more SID space: a transport of its own, its SIDs and requests in flight, its
    source address, and per destination its header prefix and SID cursor (the in-flight
    slots and the round-trip estimate stay the destination's, shared by every space).

    It is the :class:`~aiofins.transport.base.FrameSink` of its transport."""

    def __init__(self, owner: SidSpaces, number: int, transport: Transport, min_linger: float):
        self.owner = owner
        #: 1 for the first extra space (0 is the session's own).
        self.number = number
        self.transport = transport
        self.sids = SidSpace(min_linger, owner.clock)
        #: What a datagram transport reads to stop draining early (see FrameSink).
        self.replies_awaited = self.sids.pending
        self.state = SpaceState.OPENING
        #: Our address on this space (its source node: claimed, or assigned by FINS/TCP).
        self.source: FinsAddress | None = None
        #: The source node held in :data:`SOURCE_NODES` for it (UDP), and towards which peer.
        self.claimed: tuple[str, int] | None = None
        self.dests: dict[FinsAddress, DestState] = {}
        self.last_used = owner.clock()
        self.opened = anyio.Event()
        self.background: Background | None = None

    def set_source(self, source: FinsAddress) -> None:
        """Our address on this space: the source of its commands, the destination of the
        replies it may match."""
        self.source = source
        self.sids.ours = address_bits(source.network, source.node, source.unit)

    # -- the transport's sink --------------------------------------------------------------

    def frame_received(self, frame: bytes, _addr: object = None, /) -> None:
        self.owner.received(frame, None, self)

    def frame_dropped(self, reason: str) -> None:
        self.owner.dropped(reason)

    def connection_lost(self, exc: BaseException | None) -> None:
        self.owner.lost(self, exc)

    @property
    def is_open(self) -> bool:
        """Whether it carries requests (:attr:`SpaceState.OPEN`)."""
        return self.state is SpaceState.OPEN

    # -- requests --------------------------------------------------------------------------

    def dest_state(self, state: DestState) -> DestState:
        """This space's prefix and SID cursor for ``state``'s destination (its slots and
        round-trip estimate are ``state``'s)."""
        mine = self.dests.get(state.address)
        if mine is None:
            assert self.source is not None
            prefix = self.owner.prefix(state.address, self.source)
            mine = self.dests[state.address] = DestState(state.address, prefix, state.slots)
        return mine

    def __repr__(self) -> str:
        return f"<SID space {self.number} of {self.transport.description}: {self.state.name}>"


class InFlight:
    """How many requests are in flight on every SID space (``len()``; ``stats.in_flight``)."""

    __slots__ = ("pending", "spaces")

    def __init__(self, pending: dict[int, Pending]) -> None:
        self.pending = pending
        self.spaces: list[ExtraSpace] = []

    def __len__(self) -> int:
        return len(self.pending) + sum(len(s.sids.pending) for s in self.spaces)


class SidSpaces:
    """The extra SID spaces of one session (see the module's docstring)."""

    def __init__(
        self,
        transport: Transport,
        limit: int,
        min_linger: float,
        stats: SessionStats,
        hooks: EventHooks | None,
        primary: SidSpace,
        *,
        received: Callable[[bytes, object, ExtraSpace], None],
        dropped: Callable[[str], None],
        fail: Callable[[ExtraSpace, BaseException], None],
        prefix: Callable[[FinsAddress, FinsAddress], bytes],
    ) -> None:
        self.transport = transport
        #: The session's clock (see :mod:`.clock`; the session sets it on entry).
        self.clock: Clock = monotonic
        #: Spaces in all at most, the session's own included.
        self.limit = limit if transport.another() is not None else 1
        self.min_linger = min_linger
        self.stats = stats
        self.hooks = hooks
        #: The session's own space (a new space starts with the linger it has learnt).
        self.primary = primary
        self.received = received
        self.dropped = dropped
        self.fail = fail
        self.prefix = prefix
        #: The extra spaces opening or open, oldest first.
        self.extra: list[ExtraSpace] = []
        self.idle_after = IDLE_AFTER
        self.retry_at = 0.0
        self.background: Background | None = None
        self._numbers = 0
        #: The session's own source node held in SOURCE_NODES (UDP): (peer, node).
        self._primary: tuple[str, int] | None = None
        self._capped = False  # at the cap and short of SIDs (logged once per episode)

    # -- the session's own node ------------------------------------------------------------

    def primary_opened(self, node: int) -> None:
        """The session's own transport is open with source node ``node``: held, so that no
        other session's extra space takes it (UDP; nothing elsewhere)."""
        if not self.transport.own_source_node:
            return
        peer = self._peer()
        if self._primary == (peer, node):
            return
        self._release_primary()
        SOURCE_NODES.hold(peer, node)
        self._primary = (peer, node)

    def _release_primary(self) -> None:
        if self._primary is not None:
            SOURCE_NODES.release(*self._primary)
            self._primary = None

    def _peer(self) -> str:
        peer = getattr(self.transport, "peer_link", None)
        return peer if isinstance(peer, str) else self.transport.description

    # -- finding a SID ---------------------------------------------------------------------

    def take(self, state: DestState, now: float) -> tuple[int, ExtraSpace] | None:
        """A free SID of an open extra space for ``state``'s destination, and the space."""
        routed = self.primary.routed  # (a relay error is matched by SID: see SidSpace)
        for space in self.extra:
            if space.state is SpaceState.OPEN:
                space.sids.routed = routed
                key = space.sids.take(space.dest_state(state), now)
                if key is not None:
                    space.last_used = now
                    return key, space
        return None

    def allocate(self, state: DestState) -> tuple[int, ExtraSpace] | None:
        """Like :meth:`take`, looking at every SID (ends quarantines and lingers that are
        over)."""
        routed = self.primary.routed
        for space in self.extra:
            if space.state is SpaceState.OPEN:
                space.sids.routed = routed
                key = space.sids.allocate(space.dest_state(state))
                if key is not None:
                    space.last_used = self.clock()
                    return key, space
        return None

    def free_in(self, state: DestState, now: float) -> float:
        """Seconds until a SID of an open extra space may come free (see SidSpace.free_in)."""
        soonest = 1.0
        for space in self.extra:
            if space.state is SpaceState.OPEN:
                soonest = min(soonest, space.sids.free_in(space.dest_state(state), now))
        return soonest

    def share_linger(self, sids: SidSpace) -> None:
        """``sids`` has seen a duplicate reply: the lingers it has learnt, and when it saw
        the duplicate (a linger lasts while they come: :meth:`SidSpace.calm`), hold for
        every space (the peer duplicates replies, whichever socket they go to)."""
        for other in (self.primary, *(s.sids for s in self.extra)):
            other.copy_at = max(other.copy_at, sids.copy_at)
            if sids.linger > other.linger:
                other.linger = sids.linger
                other.extend_lingers(other.clock())
            other.linger_resent = max(other.linger_resent, sids.linger_resent)

    def may_open(self, now: float) -> bool:
        """Whether another space may be opened now (or one is opening)."""
        return self.background is not None and (
            any(s.state is SpaceState.OPENING for s in self.extra)
            or (len(self.extra) + 1 < self.limit and now >= self.retry_at)
        )

    async def open(self, source: FinsAddress, avoid: set[int], timeout: float) -> bool:
        """Open another space (or wait for the one opening), at most ``timeout`` seconds;
        whether one is open. The opening goes on in the background if the caller gives up.
        ``source`` is the session's own address; ``avoid`` the nodes no socket may use."""
        space = next((s for s in self.extra if s.state is SpaceState.OPENING), None)
        if space is None:
            space = self._start(source, avoid)
            if space is None:
                return False
        with anyio.move_on_after(max(timeout, 0.0)):
            await space.opened.wait()
        return space.state is SpaceState.OPEN

    def open_soon(self, source: FinsAddress, avoid: set[int]) -> None:
        """Start opening another space unless one is opening (see :meth:`open`)."""
        if not any(s.state is SpaceState.OPENING for s in self.extra):
            self._start(source, avoid)

    def _start(self, source: FinsAddress, avoid: set[int]) -> ExtraSpace | None:
        transport = self.transport.another()
        if transport is None or self.background is None:
            return None
        self._numbers += 1
        space = ExtraSpace(self, self._numbers, transport, self.min_linger)
        learnt, primary = space.sids, self.primary  # the peer's duplicates: learnt already
        learnt.linger, learnt.copy_at = primary.linger, primary.copy_at
        learnt.linger_resent = primary.linger_resent
        if transport.own_source_node:
            peer = self._peer()
            node = SOURCE_NODES.claim(peer, avoid)
            if node is None:
                self._failed(space, ConnectionLost("no free FINS source node for another socket"))
                return None
            space.claimed = (peer, node)
            space.set_source(FinsAddress(source.network, node, source.unit))
        self.extra.append(space)
        self._emit(space, None)
        self.background.start_soon(self._run, space, source)
        return space

    async def _run(self, space: ExtraSpace, source: FinsAddress) -> None:
        """Open ``space``, close it once idle: a background task ending at a boundary (a
        failure is this space's alone: counted, logged, its requests failed)."""
        assert self.background is not None
        space.background = self.background.child(lambda e: self.lost(space, e))
        transport = space.transport
        try:
            await transport.open(space, space.background)
            if space.source is None:  # FINS/TCP: the node the PLC assigned
                node = transport.local_node
                if node is None or not 1 <= node <= 254:
                    raise ConnectionLost(f"{transport.description} assigned us FINS node {node}")
                space.set_source(FinsAddress(source.network, node, source.unit))
        except Exception as exc:
            with anyio.CancelScope(shield=True):
                await self._close(space)
            self._failed(space, exc)
            return
        if space.state is not SpaceState.OPENING:  # the session closed meanwhile
            return
        self.stats.sid_spaces_opened += 1
        assert space.source is not None
        where = transport.description
        logger.info(
            "%s: SIDs short: opened SID space %d (%s, source node %d; %d of at most %d)",
            where,
            space.number,
            "another connection" if transport.fresh_sid_space else "another socket",
            space.source.node,
            len(self.extra) + 1,
            self.limit,
            extra={"endpoint": where, "node": space.source.node},
        )
        self.move(space, SpaceState.OPEN)
        space.opened.set()
        while space.is_open:
            idle_at = space.last_used + self.idle_after
            now = self.clock()
            if now < idle_at or space.sids.pending or self._capped:  # (capped: needed)
                await anyio.sleep(max(idle_at - now, self.idle_after / 4))
                continue
            if logger.isEnabledFor(logging.DEBUG):
                logger.debug(
                    "%s: SID space %d idle for %.1f s: closed",
                    where,
                    space.number,
                    now - space.last_used,
                    extra={"endpoint": where},
                )
            with anyio.CancelScope(shield=True):
                await self._close(space)

    def _failed(self, space: ExtraSpace, exc: BaseException) -> None:
        self.stats.sid_space_failures += 1
        self.retry_at = self.clock() + RETRY_AFTER
        where = self.transport.description
        logger.warning(
            "%s: cannot open another SID space (%s); requests wait for a free SID",
            where,
            exc,
            extra={"endpoint": where},
        )
        space.opened.set()

    def lost(self, space: ExtraSpace, exc: BaseException | None) -> None:
        """``space``'s link failed: its requests fail (quarantined), it is closed."""
        if space.state is SpaceState.CLOSED or space.state is SpaceState.CLOSING:
            return
        where = space.transport.description
        logger.info(
            "%s: SID space %d lost its link: %s",
            where,
            space.number,
            exc,
            extra={"endpoint": where},
        )
        self.move(space, SpaceState.CLOSING)
        self.fail(space, ConnectionLost(f"{where}: SID space {space.number} lost: {exc}"))
        if self.background is not None:
            self.background.start_soon(self._close, space)

    async def _close(self, space: ExtraSpace) -> None:
        """Close ``space``'s transport; its node (UDP) cools while a late reply may come."""
        if space.state is SpaceState.CLOSED:
            return
        if space.state is not SpaceState.CLOSING:
            self.move(space, SpaceState.CLOSING)
        if space.sids.pending:
            self.fail(space, ConnectionLost(f"SID space {space.number} closed"))
        sids = space.sids
        until = max([*sids.quarantine.values(), *sids.lingering.values(), 0.0])
        try:
            await space.transport.aclose()
        finally:
            if space.background is not None:
                space.background.cancel_all()
            if space.claimed is not None:
                SOURCE_NODES.release(*space.claimed, cool_until=until, clock=self.clock)
                space.claimed = None
            if space in self.extra:
                self.extra.remove(space)
            self.move(space, SpaceState.CLOSED)
            space.opened.set()

    async def aclose(self) -> None:
        """The session closes: every extra space with it, the session's own node given
        back."""
        for space in list(self.extra):
            await self._close(space)
        self._release_primary()

    # -- the one place a space changes state --------------------------------------------------

    def move(self, space: ExtraSpace, new: SpaceState) -> None:
        """Move ``space`` to ``new``: checked against :data:`SPACE_TRANSITIONS`, logged
        (DEBUG), emitted as a :class:`SidSpaceChanged` hook event."""
        old = space.state
        assert new in SPACE_TRANSITIONS[old], f"SID space {old.name} -> {new.name}"
        space.state = new
        if logger.isEnabledFor(logging.DEBUG):
            where = space.transport.description
            logger.debug(
                "%s: SID space %d: %s -> %s",
                where,
                space.number,
                old.name,
                new.name,
                extra={"endpoint": where},
            )
        self._emit(space, old)

    def _emit(self, space: ExtraSpace, old: SpaceState | None) -> None:
        hooks = self.hooks
        if hooks is not None and hooks.sid_space_changed:
            hooks.emit(
                hooks.sid_space_changed,
                SidSpaceChanged(
                    space.transport.description,
                    space.number,
                    None if old is None else old.name,
                    space.state.name,
                    None if space.source is None else space.source.node,
                ),
            )

    # -- running short ---------------------------------------------------------------------

    def short(self, dest: FinsAddress, new_episode: bool) -> None:
        """Every SID of every space is taken and no other may be opened: logged once per
        episode (``new_episode``: the first shortage after :data:`SHORTAGE_EPISODE` without
        one; the caller counts every one)."""
        self._capped = True
        if not new_episode:
            return
        where = self.transport.description
        logger.warning(
            "%s: all SIDs of %s in all %d SID spaces are taken (at most %d: max_sid_spaces): "
            "requests wait for one; lower the rate or the linger, or allow more spaces",
            where,
            dest,
            len(self.extra) + 1,
            self.limit,
            extra={"endpoint": where, "dest": str(dest)},
        )

    def enough(self) -> None:
        """A SID was found again: spaces may close when idle (the shortage's warning is
        not repeated before :data:`SHORTAGE_EPISODE` has passed without one)."""
        self._capped = False


class SidUser(Protocol):
    """What a request waiting for a free SID uses of its session (a
    :class:`~aiofins.session.Session`): :func:`sid_anywhere`, :func:`evidence_probe`,
    :func:`start_when_free`."""

    @property
    def transport(self) -> Transport: ...

    @property
    def source(self) -> FinsAddress: ...

    @property
    def sids(self) -> SidSpace: ...

    @property
    def spaces(self) -> SidSpaces: ...

    @property
    def stats(self) -> SessionStats: ...

    @property
    def timeout(self) -> float: ...

    def clock(self) -> float: ...

    def nodes_in_use(self) -> set[int]: ...

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
    ) -> bytes | None: ...

    def abandon(self, p: Pending, timeout: float, timed_out: bool = False) -> None: ...


async def sid_anywhere(
    session: SidUser, state: DestState, end: float, timeout: float
) -> tuple[int, ExtraSpace | None]:
    """A free SID (and the extra space it belongs to, ``None``: the session's own) when
    the next one of the session's own space is taken: another of its own, one of an
    open extra space, or one of a space opened now (see :mod:`.spaces`). At the cap,
    wait for the first to come free in any space, up to the call's deadline ``end``
    (then :class:`SlotTimeout`). Running out is counted and logged (once until SIDs
    are free again)."""
    sids, spaces, clock = session.sids, session.spaces, session.clock
    key = sids.allocate(state)
    if key is not None:
        spaces.enough()
        return key, None
    got = spaces.allocate(state)
    while got is None and spaces.may_open(clock()):
        if not await spaces.open(session.source, session.nodes_in_use(), end - clock()):
            break
        got = spaces.allocate(state)
    if got is not None:
        spaces.enough()
        return got
    _ran_out(session, state)
    # One waiter at a time looks for a SID (a scan of 256 is not free); the others queue
    # behind it, first come first served.
    lock = state.sid_lock
    if lock is None:
        lock = state.sid_lock = anyio.Lock()
    probe_at = clock()
    with anyio.move_on_after(max(end - clock(), 0.0)):
        async with lock:
            while True:
                key = sids.allocate(state)
                if key is not None:
                    return key, None
                got = spaces.allocate(state)
                if got is not None:
                    return got
                now = clock()
                if spaces.may_open(now):
                    await spaces.open(session.source, session.nodes_in_use(), end - now)
                    continue
                if now >= probe_at and state.base in sids.given_up:
                    probe_at = now + session.timeout
                    await evidence_probe(session, state, min(end, probe_at))
                    continue
                wait = min(SID_WAIT, sids.free_in(state, now), spaces.free_in(state, now))
                await anyio.sleep(wait)
    raise no_free_sid(session.sids, state, timeout)


def _ran_out(session: SidUser, state: DestState) -> None:
    """Every SID of ``state``'s destination is taken in every space the session may have:
    counted, and said (a WARNING once per shortage episode, see :data:`SHORTAGE_EPISODE`;
    with extra spaces allowed, by :meth:`SidSpaces.short`)."""
    sids, spaces = session.sids, session.spaces
    session.stats.sid_exhausted += 1
    now = session.clock()
    new_episode = now - sids.short_at >= SHORTAGE_EPISODE
    sids.short_at = now
    if spaces.limit > 1:
        spaces.short(state.address, new_episode)
    elif new_episode:
        logger.warning(
            "%s: all 256 SIDs of %s are taken (%d in flight, %d quarantined, "
            "%d lingering): requests wait for one; lower the rate or the linger",
            session.transport.description,
            state.address,
            len(sids.pending),
            len(sids.quarantine),
            len(sids.lingering),
            extra={"endpoint": session.transport.description, "dest": str(state.address)},
        )


#: The commands an evidence probe sends (a harmless read of the CPU Unit's status, or of
#: its controller data when the request given up on was that status read).
PROBES = ((0x06, 0x01), (0x05, 0x01))


async def evidence_probe(session: SidUser, state: DestState, end: float) -> None:
    """Every SID of ``state``'s destination is taken and some are quarantined for requests
    given up on: ask the destination whether it answers, under the SID given up on
    longest ago, with a command other than that request's (so a late reply to it is
    counted as mismatched, never taken for the probe's), waiting until ``end``. Any answer
    is the evidence that ends those quarantines (:meth:`SidSpace.answered_after`); no
    answer quarantines the SID again. Without it, a PLC silent long enough for every SID
    to be given up on (max_sid_spaces=1, many requests in flight) left no SID free to learn
    that it answers again until ``min_quarantine`` (15 s) had passed."""
    sids = session.sids
    mine = sids.given_up.get(state.base)
    if not mine:
        return
    key = min(mine, key=lambda k: mine[k][0])
    command = mine[key][1]
    mrc, src = next(c for c in PROBES if (c[0] << 8) | c[1] != command)
    if key in sids.pending:  # (taken meanwhile)
        return
    until = sids.quarantine.pop(key, None)
    sids.lingering.pop(key, None)
    cursor = state.cursor
    state.cursor = key & 0xFF
    p = EventPending(0, mrc, src)
    now = session.clock()
    try:
        frame = session.start(p, state, mrc, src, b"", 0, now, max(end, now + 0.001), None)
    finally:
        state.cursor = cursor
        if until is not None:
            sids.quarantine[key] = until  # (until the evidence, or its own give-up)
    if frame is None:
        return
    session.stats.sid_probes += 1
    try:
        transport = session.transport
        if transport.fast_send is not None:
            transport.fast_send(frame)
        else:
            await transport.send(frame, max(end - now, 0.001))
        await p.wait()
    except Exception:  # no answer (or the link failed): the probe's SID is quarantined
        session.abandon(p, session.timeout)
    except BaseException:
        session.abandon(p, session.timeout)
        raise


async def start_when_free(
    session: SidUser,
    p: Pending,
    state: DestState,
    command: tuple[int, int, bytes],
    retries: int,
    end: float,
    cap: float | None,
    timeout: float,
) -> tuple[bytes, Transport, float]:
    """:meth:`Session.start` for a request that found the next SIDs of ``state`` taken:
    once :func:`sid_anywhere` found a free one (waiting up to ``end``), ``p`` is started
    on it (``timeout``: the call's, for the error). Returns the frame, the transport to
    send it on and the time it was started."""
    mrc, src, params = command
    # The SID found is free and stays so until start() takes it.
    key, space = await sid_anywhere(session, state, end, timeout)
    transport = session.transport
    if space is None:
        state.cursor = key & 0xFF
    else:  # on another socket or connection
        space.dest_state(state).cursor = key & 0xFF
        transport = space.transport
    now = session.clock()
    frame = session.start(p, state, mrc, src, params, retries, now, end, cap, space)
    assert frame is not None
    return frame, transport, now
