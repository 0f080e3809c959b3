"""The deadline watcher: the session's one timer for every request in flight.

Each request in flight has a deadline (:attr:`Pending.deadline`) in one
:class:`~aiofins.session.deadlines.Deadlines` structure. One background task sleeps until the
earliest; when it wakes, each request that is due is either sent again (same frame, same SID,
still registered: whichever reply comes first answers it; RFC 6298's doubling wait) or given
up on (its SID quarantined, the caller failed with a timeout). No task and no timer per
request: a new request only moves the watcher's wake-up earlier when its deadline is the
earliest (:meth:`DeadlineWatcher.arm`).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from time import monotonic
from typing import Any, Protocol

import anyio

from .._compiling import python_class
from ..hooks import EventHooks, RequestRetried, RequestTimedOut
from ..protocol.errors import ConnectionLost, FinsError, FinsTimeout
from ..protocol.frames import key_address
from ..protocol.header import FinsAddress
from ..transport.base import Transport
from .background import Background
from .breaker import CircuitBreaker
from .deadlines import Deadlines
from .response import SessionStats
from .sids import SidSpace
from .slots import Pending, Retransmission

logger = logging.getLogger("aiofins.session")
_DEBUG = logging.DEBUG


#: :attr:`DeadlineWatcher.at` of a watcher whose session is driven without an event loop
#: (the blocking driver reads the deadlines itself as it waits): never armed or disarmed.
TIMERLESS = -math.inf


@python_class
class Expired(FinsTimeout):
    """A request's deadline passed after every transmission (the caller words the message)."""


class Watched(Protocol):
    """What the watcher uses of the session it serves (a :class:`~aiofins.session.Session`)."""

    @property
    def transport(self) -> Transport: ...

    @property
    def sids(self) -> SidSpace: ...

    @property
    def stats(self) -> SessionStats: ...

    @property
    def rto_bounds(self) -> tuple[float, float]: ...

    @property
    def adaptive(self) -> bool: ...

    def quarantine_until(self, now: float, timeout: float) -> float: ...

    def emit(
        self, handlers: list[Any], event: Callable[..., Any], p: Pending, *more: Any
    ) -> None: ...

    def fail_all(self, exc: BaseException) -> None: ...


class DeadlineWatcher:
    """Retransmits or gives up the requests of ``session`` whose deadline is due."""

    def __init__(self, session: Watched, breaker: CircuitBreaker, hooks: EventHooks | None) -> None:
        self.session = session
        self.breaker = breaker
        self.hooks = hooks
        self.deadlines = Deadlines()
        #: The in-order part of the deadlines, appended to inline by the session.
        self.fifo = self.deadlines.fifo
        #: When the watcher wakes next (the session's clock; ``inf``: not before a request
        #: is added).
        self.at = math.inf
        #: The watcher's sleep under anyio's other backends (trio): a cancel scope's deadline.
        self.scope: anyio.CancelScope | None = None
        #: Under asyncio: the loop, the future the watcher sleeps on, and the timer that
        #: resolves it (a bare future and ``call_at``: a wake-up costs one task step, not a
        #: cancellation).
        self.loop: Any = None
        self.waiter: asyncio.Future[None] | None = None
        self.timer: asyncio.TimerHandle | None = None
        #: The session's clock, the backend timer's, and whether a time of the first may be
        #: given to the timer as it is (all set by the session on entry; see ``.clock``).
        self.clock: Callable[[], float] = monotonic
        self.timer_clock: Callable[[], float] = monotonic
        self.direct = True
        self.background: Background | None = None
        self._fire = self.fire  # (bound once: arm() passes it to every timer)
        #: Work a receive callback asked to be done from a task (see :meth:`from_task`).
        self.chores: list[Callable[[], None]] = []
        #: Passes its task has made over the deadlines (each wake-up of the task is one).
        self.passes = 0
        #: Whether the session cancels the timer when the last deadline is answered
        #: (:meth:`disarm`): set when the timer fired with nothing left to do (a paced
        #: caller, answered before each deadline, the next request after it), cleared when
        #: a request comes while the timer cancelled would still have been pending (a
        #: caller sending back to back, whose requests that timer covered).
        self.disarms = False
        #: When the timer :meth:`disarm` cancelled would have fired.
        self.parked = 0.0

    def from_task(self, chore: Callable[[], None]) -> None:
        """Run ``chore`` from the watcher's task at its next wake-up, which this causes:
        for work a receive callback cannot do itself, such as starting a task (anyio
        starts one only from a task; a batch finding no free SID runs in a callback)."""
        self.chores.append(chore)
        waiter = self.waiter
        if waiter is not None:
            if not waiter.done():
                waiter.set_result(None)
        elif self.scope is not None:
            self.scope.cancel()

    def _run_chores(self) -> None:
        chores, self.chores = self.chores, []
        for chore in chores:
            chore()

    def fire(self) -> None:
        """The asyncio timer's callback. Wakes the watcher only if a request is due: when
        the requests it was armed for were answered meanwhile (a paced caller: one request
        every scan, answered long before its retransmission timeout), it re-arms for the
        earliest request still in flight, or sleeps until the next request arms it, without
        a task step."""
        self.timer = None
        waiter = self.waiter
        if waiter is None or waiter.done():
            return
        at = self.deadlines.live_earliest()
        now = self.clock()
        if at <= now:
            waiter.set_result(None)
            return
        self.at = at
        self.disarms = at == math.inf  # (fired for nothing: cancel it next time)
        if at != math.inf:
            self.timer = self.loop.call_at(
                at if self.direct else self.timer_clock() + (at - now), self._fire
            )

    async def run(self) -> None:
        """The only timer: sleeps until the earliest deadline, retransmits or expires what is
        due. A boundary: an error here fails the requests in flight, never the task group."""
        loop = self.loop
        while True:
            try:
                self.passes += 1
                if self.chores:
                    self._run_chores()
                self.expire(self.clock())
            except Exception as exc:  # a bug: fail what is in flight, keep the timer alive
                where = self.session.transport.description
                logger.exception("%s: deadline watcher failed", where, extra={"endpoint": where})
                self.session.fail_all(ConnectionLost(f"session error: {exc!r}"))
            if self.chores:  # (asked for while expiring)
                continue
            at = self.deadlines.earliest()
            self.at = at
            self.disarms = at == math.inf  # (nothing left: a timer would fire for nothing)
            if loop is not None:
                waiter = self.waiter = loop.create_future()
                if at != math.inf:
                    if not self.direct:
                        at = loop.time() + (at - self.clock())
                    self.timer = loop.call_at(at, self._fire)
                try:
                    await waiter
                finally:
                    self.waiter = None
                    timer, self.timer = self.timer, None
                    if timer is not None:
                        timer.cancel()
                continue
            with anyio.CancelScope() as scope:
                self.scope = scope
                if at != math.inf:
                    scope.deadline = at if self.direct else self.timer_clock() + (at - self.clock())
                await anyio.sleep_forever()
            self.scope = None

    def arm(self, deadline: float, now: float) -> None:
        """Wake the watcher at ``deadline`` (the session's clock; ``now``: the request's
        sending time) if that is earlier than planned. Runs in receive callbacks too (a
        batch sends from there), so the backend's clock is read directly rather than
        through ``anyio.current_time()``, which needs a task."""
        if deadline >= self.at:
            return
        if now < self.parked:  # the timer disarm() cancelled would have served: keep them
            self.disarms = False
        waiter = self.waiter
        if waiter is not None:
            self.at = deadline
            timer = self.timer
            if timer is not None:
                timer.cancel()
            self.timer = self.loop.call_at(
                deadline if self.direct else self.timer_clock() + (deadline - self.clock()),
                self._fire,
            )
            return
        scope = self.scope
        if scope is not None:
            self.at = deadline
            scope.deadline = (
                deadline if self.direct else self.timer_clock() + (deadline - self.clock())
            )

    def disarm(self) -> None:
        """No request has a deadline any more (the last one was answered) and the timer
        fires for nothing here (:attr:`disarms`): it is cancelled; the next request arms it
        again (:meth:`arm`). A paced caller's request is answered long before its
        deadline and the next comes after it: this saves the timer's dispatch and
        :meth:`fire` per request (a back-to-back caller keeps one timer for many)."""
        self.parked = self.at
        self.at = math.inf
        timer = self.timer
        if timer is not None:
            self.timer = None
            timer.cancel()
        elif self.scope is not None:
            self.scope.deadline = math.inf

    def expire(self, now: float) -> None:
        """Send again or give up every request due at ``now``."""
        session = self.session
        for p in self.deadlines.due(now):
            plan = p.plan
            if plan is not None:
                if type(plan) is tuple:  # the first retransmission: now an object
                    plan = p.plan = Retransmission(*plan)
                assert isinstance(plan, Retransmission)
                if now < plan.end:
                    if plan.left:
                        self.retransmit(p, plan, now)
                        continue
                    if plan.cap is None and p.deadline < plan.end:  # the last: presumed lost
                        self._presumed_lost(p, plan)
                        continue
            (session.sids if p.space is None else p.space.sids).abandon(
                p, session.quarantine_until(now, now - p.sent_at)
            )
            p.free_slot()  # at once, not when its caller next runs
            session.stats.timeouts += 1
            self._log_timeout(p, now)
            hooks = self.hooks
            if hooks is not None and hooks.request_timed_out:
                session.emit(
                    hooks.request_timed_out, RequestTimedOut, p, p.attempts, now - p.sent_at
                )
            p.fail(Expired("request timed out"))

    def _presumed_lost(self, p: Pending, plan: Retransmission) -> None:
        """No reply to ``p``'s last transmission within its retransmission timeout: the
        datagram is presumed lost and occupies none of the PLC's capacity, so the slot
        goes to the next caller; ``p`` still waits for a late reply (its SID registered)
        until its call's deadline."""
        p.free_slot()
        p.deadline = plan.end
        self.deadlines.add(p)

    def _log_timeout(self, p: Pending, now: float) -> None:
        """A request got no reply after its last transmission: a WARNING for the first
        such call after an answered one (a dead PLC warns once, not per request), DEBUG for
        the next ones."""
        first = not self.breaker.failures
        if not first and not logger.isEnabledFor(_DEBUG):
            return
        where = self.session.transport.description
        key = p.key
        dest = FinsAddress(*key_address(key))
        logger.log(
            logging.WARNING if first else _DEBUG,
            "%s: no reply from %s to SID %d (command %02X%02X) after %d transmission(s) in %.3f s",
            where,
            dest,
            key & 0xFF,
            p.mrc,
            p.src,
            p.attempts,
            now - p.sent_at,
            extra={
                "endpoint": where,
                "node": dest.node,
                "sid": key & 0xFF,
                "command": f"{p.mrc:02X}{p.src:02X}",
            },
        )

    def retransmit(self, p: Pending, resend: Retransmission, now: float) -> None:
        """Send ``p`` again: the same frame and SID, still registered, so whichever reply
        comes first answers it. The wait doubles (RFC 6298 5.5); the last attempt waits
        until the call's deadline (or the caller's per-attempt cap)."""
        session = self.session
        resend.left -= 1
        p.attempts += 1
        p.rtt = None  # Karn: a reply can no longer be timed
        wait = 2 * resend.wait
        if session.adaptive and wait > session.rto_bounds[1]:  # (a stream: the call's plan)
            wait = session.rto_bounds[1]
        cap = resend.cap
        if cap is not None and wait > cap:
            wait = cap
        resend.wait = wait
        if resend.left or cap is None:
            deadline = now + wait  # the last: then presumed lost (see _presumed_lost)
        else:
            deadline = now + cap
        p.deadline = min(deadline, resend.end)
        self.deadlines.add(p)
        session.stats.retries += 1
        key = p.key
        transport = session.transport if p.space is None else p.space.transport
        if logger.isEnabledFor(_DEBUG):
            logger.debug(
                "%s: no reply to SID %d (command %02X%02X) within %.3f s: sent again (attempt %d)",
                transport.description,
                key & 0xFF,
                p.mrc,
                p.src,
                now - p.sent_at,
                p.attempts,
                extra={
                    "endpoint": transport.description,
                    "sid": key & 0xFF,
                    "command": f"{p.mrc:02X}{p.src:02X}",
                },
            )
        hooks = self.hooks
        if hooks is not None and hooks.request_retried:
            session.emit(hooks.request_retried, RequestRetried, p, p.attempts, now - p.sent_at)
        fast_send = transport.fast_send
        if fast_send is not None:
            try:
                fast_send(resend.frame)
            except Exception as exc:
                self.give_up(p, exc)
        elif self.background is not None:
            self.background.start_soon(self._resend, p, resend)

    async def _resend(self, p: Pending, resend: Retransmission) -> None:
        """A retransmission through an awaited send (trio, FINS/TCP under anyio)."""
        transport = self.session.transport if p.space is None else p.space.transport
        try:
            await transport.send(resend.frame, max(resend.end - self.clock(), 0.001))
        except Exception as exc:  # a boundary: the request fails, nothing else
            self.give_up(p, exc)

    def give_up(self, p: Pending, exc: BaseException) -> None:
        """``p`` cannot go on (its retransmission failed): out of the table, SID quarantined,
        the caller told why."""
        if p.done:
            return
        session = self.session
        now = self.clock()
        (session.sids if p.space is None else p.space.sids).abandon(
            p, session.quarantine_until(now, now - p.sent_at)
        )
        if not isinstance(exc, FinsError):
            where = session.transport.description
            err = ConnectionLost(f"{where}: {exc or type(exc).__name__}")
            err.__cause__ = exc
            exc = err
        p.fail(exc)
