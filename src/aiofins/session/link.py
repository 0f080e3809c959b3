"""The session's link: opening its transport, reconnecting after a loss, the backoff.

:class:`Link` holds the :class:`~aiofins.session.states.LinkState` and is the one place it
changes (:meth:`Link.set_state`, checked against :data:`LINK_TRANSITIONS`, logged, emitted
as :class:`~aiofins.hooks.ConnectionStateChanged`). One connection attempt runs at a time, in
the background, shared by every caller that needs the link meanwhile; each waits for it at
most its own deadline. A failed attempt starts a jittered backoff during which calls fail at
once (:class:`InBackoff`).
"""

from __future__ import annotations

import logging
import random
from collections.abc import Callable
from time import monotonic
from types import TracebackType

import anyio

from ..hooks import ConnectionStateChanged, EventHooks
from ..protocol.errors import ConnectionLost, FinsError, FinsTimeout
from ..transport.base import FrameSink, Transport
from .background import Background
from .clock import Clock
from .response import SessionStats
from .states import LINK_TRANSITIONS, LinkState

logger = logging.getLogger("aiofins.session")
_DEBUG = logging.DEBUG


class InBackoff(ConnectionLost):
    """Failed at once during the reconnect backoff (the failed attempt was counted)."""


class _Attempt:
    """One connection attempt, run in the background and shared by every caller that needs
    the link while it runs; each waits for it at most its own deadline."""

    __slots__ = ("done", "error", "traceback")

    def __init__(self) -> None:
        self.done = anyio.Event()
        self.error: BaseException | None = None
        self.traceback: TracebackType | None = None

    def finish(self, error: BaseException | None) -> None:
        """The outcome (``None``: connected); the first one counts."""
        if not self.done.is_set():
            self.error = error
            self.traceback = None if error is None else error.__traceback__
            self.done.set()

    def check(self) -> None:
        """Raise the attempt's error, if any (to each waiter, as an asyncio future does)."""
        if self.error is not None:
            raise self.error.with_traceback(self.traceback)


class Link:
    """The link state of one session's transport (see the module's docstring).

    ``on_open`` runs once the transport is open, before the link counts as open: it may
    raise (a peer assigned a node no header can carry) to fail the attempt. ``on_fresh``
    runs when a new connection starts a clean SID space (``transport.fresh_sid_space``).
    """

    def __init__(
        self,
        transport: Transport,
        sink: FrameSink,
        stats: SessionStats,
        reconnect_backoff: tuple[float, float],
        hooks: EventHooks | None,
        on_open: Callable[[], None],
        on_fresh: Callable[[], None],
        fail: Callable[[BaseException], None],
        clock: Clock = monotonic,
    ) -> None:
        #: The session's clock (see :mod:`.clock`).
        self.clock = clock
        self.transport = transport
        self.sink = sink
        self.stats = stats
        self.reconnect_backoff = reconnect_backoff
        self.hooks = hooks
        self.on_open = on_open
        self.on_fresh = on_fresh
        self.fail = fail
        self.background: Background | None = None
        self.state = LinkState.CLOSED
        self.since = clock()
        self.lost_at: float | None = None  # when an open link was lost (for "reconnected")
        #: The connection attempt in progress, if any (one at a time, shared by callers).
        self.connecting: _Attempt | None = None
        self.backoff = 0.0
        self.retry_at = 0.0  # no connection attempt before this time (the clock's)

    def set_state(self, new: LinkState) -> None:
        """The one place the link state changes: checked, logged, emitted as a hook."""
        old = self.state
        if new is old:
            return
        assert new in LINK_TRANSITIONS[old], f"link state {old.name} -> {new.name}"
        self.state = new
        now = self.clock()
        self.since = now
        where = self.transport.description
        if new is LinkState.OPEN:
            lost = self.lost_at
            if lost is None:
                logger.info("connected to %s", where, extra={"endpoint": where})
            else:
                logger.info(
                    "reconnected to %s after %.1f s",
                    where,
                    now - lost,
                    extra={"endpoint": where},
                )
            self.lost_at = None
        elif new is LinkState.CLOSED and old is LinkState.OPEN:
            self.lost_at = now
        elif new is LinkState.SHUT:
            logger.info("session to %s closed", where, extra={"endpoint": where})
        if logger.isEnabledFor(_DEBUG):
            logger.debug(
                "link to %s: %s -> %s", where, old.name, new.name, extra={"endpoint": where}
            )
        hooks = self.hooks
        if hooks is not None and hooks.connection_state_changed:
            hooks.emit(
                hooks.connection_state_changed,
                ConnectionStateChanged(where, old.name, new.name),
            )

    def shut(self) -> bool:
        """Closed for good (``aclose``): the attempt in progress, if any, fails its waiters
        at once. ``False`` if it was shut already."""
        if self.state is LinkState.SHUT:
            return False
        self.set_state(LinkState.SHUT)
        attempt, self.connecting = self.connecting, None
        if attempt is not None:  # its waiters fail now; cancel_all() ends the attempt itself
            attempt.finish(
                ConnectionLost(f"session to {self.transport.description} closed while connecting")
            )
        return True

    def lost(self) -> None:
        """The open link failed (counted by the caller): closed until the next call."""
        if self.state is LinkState.OPEN:
            self.set_state(LinkState.CLOSED)

    def connection_lost(self, exc: BaseException | None) -> None:
        """The transport says its link ended (``exc``: why): counted, logged, the link
        closed until the next call, the requests in flight failed (``fail``) with a
        :class:`ConnectionLost` (or ``exc`` itself if it is a FINS error)."""
        if self.state is LinkState.SHUT:
            return
        self.stats.disconnects += 1
        where = self.transport.description
        if isinstance(exc, FinsError):
            err: FinsError = exc
        else:
            err = ConnectionLost(f"connection to {where} lost: {exc}")
            err.__cause__ = exc
        if self.state is LinkState.OPEN:
            logger.info("connection to %s lost: %s", where, err, extra={"endpoint": where})
            self.lost()
        self.fail(err)

    def background_failed(self, exc: Exception) -> None:
        """A background task (the transport's reader, a retransmission) raised: the link is
        considered lost (requests in flight fail with :class:`ConnectionLost`), logged and
        counted; the caller's task group never sees it."""
        self.stats.background_errors += 1
        where = self.transport.description
        logger.warning(
            "%s: background task failed: %r", where, exc, exc_info=exc, extra={"endpoint": where}
        )
        err = ConnectionLost(f"connection to {where} failed: {exc or type(exc).__name__}")
        err.__cause__ = exc
        if self.state is LinkState.OPEN:
            self.stats.disconnects += 1
            self.lost()
        self.fail(err)

    async def ensure_open(
        self, timeout: float | None = None, *, call_timeout: float | None = None
    ) -> None:
        """Open the transport if it is closed, waiting for it at most ``timeout`` seconds
        (``call_timeout``: the whole call's, which the error names; default ``timeout``).

        One connection attempt at a time, run in the background (bounded by the transport's
        own connect timeout) and shared by every caller that comes while it runs. A caller
        whose ``timeout`` passes first gets :class:`FinsTimeout` and leaves the attempt
        running: a later call finds the link open or keeps waiting for the same attempt.
        During the backoff after a failed attempt calls fail at once. ``timeout=None``
        waits for the attempt's outcome (``async with session``).
        """
        if self.transport.is_open:
            return
        if self.state is not LinkState.SHUT and self.background is None:
            raise RuntimeError("Session is not running: use 'async with Session(...)'")
        self.may_connect()
        background = self.background
        assert background is not None
        attempt = self.connecting
        if attempt is None:
            attempt = self.connecting = _Attempt()
            self.set_state(LinkState.CONNECTING)
            background.start_soon(self._connect, attempt)
        if timeout is None:
            await attempt.done.wait()
        else:
            with anyio.move_on_after(max(timeout, 0.0)):
                await attempt.done.wait()
            if not attempt.done.is_set():
                raise FinsTimeout(
                    f"no connection to {self.transport.description} within "
                    f"{timeout if call_timeout is None else call_timeout:.3g} s: "
                    "a connection attempt is still in progress (a later call uses it once "
                    "it succeeds)"
                )
        attempt.check()

    def may_connect(self) -> None:
        """Before a connection attempt (the transport is closed): raise
        :class:`ConnectionLost` if the link is shut, :class:`InBackoff` while the backoff
        after a failed attempt runs (calls fail fast: none waits it out beyond its own
        deadline); a link still ``OPEN`` (the transport ended without telling us) is
        ``CLOSED`` now."""
        state = self.state
        if state is LinkState.SHUT:
            raise ConnectionLost(f"session to {self.transport.description} is closed")
        if state is LinkState.OPEN:  # the transport ended without telling us
            self.set_state(LinkState.CLOSED)
        elif state is LinkState.BACKOFF:
            wait = self.retry_at - self.clock()
            if wait > 0:
                raise InBackoff(
                    f"cannot connect to {self.transport.description}: the last attempt failed; "
                    f"the next one in {wait:.2f} s (reconnect backoff)"
                )

    def opened(self) -> None:
        """The transport is open (``on_open`` ran and accepted it): counted, logged, the
        SID space made fresh if it is, the link ``OPEN``. The success of every connection
        attempt, the event-loop one's (:meth:`_connect`) and a blocking driver's."""
        transport = self.transport
        where = transport.description
        self.backoff = 0.0
        self.stats.connects += 1
        if transport.local_node is not None:
            logger.info(
                "%s allocated us FINS node %d (its own node: %s)",
                where,
                transport.local_node,
                transport.remote_node,
                extra={"endpoint": where, "node": transport.local_node},
            )
        if transport.fresh_sid_space:  # nothing late can reach a new connection
            self.on_fresh()
        self.set_state(LinkState.OPEN)

    def open_failed(self, error: FinsError, exc: BaseException) -> None:
        """A connection attempt failed with ``exc`` (``error``: as the callers get it; the
        transport is closed): unless the link is shut, counted, logged, and the link in
        ``BACKOFF`` for the next, jittered, doubling wait. The failure of every connection
        attempt, the event-loop one's (:meth:`_connect`) and a blocking driver's."""
        if self.state is LinkState.SHUT:
            return
        where = self.transport.description
        self.stats.connect_failures += 1
        low, high = self.reconnect_backoff
        self.backoff = min(high, max(low, self.backoff * 2))
        wait = self.backoff * random.uniform(0.5, 1.0)  # no lockstep after an outage
        self.retry_at = self.clock() + wait
        self.set_state(LinkState.BACKOFF)
        logger.warning(
            "%s; next attempt in %.2f s",
            # The error names the endpoint already, or is prefixed with it.
            error if where in str(error) else f"cannot connect to {where}: {error}",
            wait,
            exc_info=not isinstance(exc, (OSError, FinsError)),
            extra={"endpoint": where},
        )

    async def _connect(self, attempt: _Attempt) -> None:
        """Run one connection attempt: a background task ending at a boundary. Whatever goes
        wrong (a refused connection, a peer assigning a node no FINS header can carry, a bug)
        is a failed attempt: link closed, a typed error to the waiters, counted, logged,
        never raised into the task group; success is reported only once all is checked."""
        error: FinsError | None = None
        transport = self.transport
        where = transport.description
        try:
            assert self.background is not None
            await transport.open(self.sink, self.background)
            self.on_open()
        except BaseException as exc:
            if isinstance(exc, FinsError):
                error = exc
            elif isinstance(exc, Exception):
                error = ConnectionLost(f"cannot connect to {where}: {exc or type(exc).__name__}")
                error.__cause__ = exc
            else:  # cancelled: the session is closing
                error = ConnectionLost(f"session to {where} closed while connecting")
            with anyio.CancelScope(shield=True):
                await transport.aclose()
            if self.connecting is attempt:
                self.connecting = None
            if isinstance(exc, Exception):
                self.open_failed(error, exc)
            attempt.finish(error)
            if not isinstance(exc, Exception):
                raise
            return
        if self.connecting is attempt:
            self.connecting = None
        if self.state is LinkState.SHUT:  # closed as the open completed: leave no link behind
            with anyio.CancelScope(shield=True):
                await transport.aclose()
            attempt.finish(ConnectionLost(f"session to {where} is closed"))
            return
        self.opened()
        attempt.finish(None)
