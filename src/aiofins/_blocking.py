"""The blocking client's session driver: a request's steps run from the calling thread.

A :class:`~aiofins.session.Session` holds every rule of a request, in synchronous steps that
do no I/O and take the session's clock: :meth:`Session.begin` (checks, slot, SID, frame,
registration, deadline, hooks, log, the send through ``transport.fast_send``),
:meth:`Session.frame_received` (matching, RTT, linger, stats), the deadline watcher's
:meth:`~aiofins.session.watcher.DeadlineWatcher.expire` (retransmissions and give-ups),
:meth:`Session.finish` (end code, counters, CPU flags, breaker, the busy decision) and
:meth:`Session.failure` (a request given up, the error worded, the breaker told); the link's
attempts (:class:`~aiofins.session.link.Link`). Under an event loop a request awaits once
between them; here :class:`BlockingDriver` waits on a blocking socket
(:mod:`aiofins.transport.blocking`) instead, for as long as the session's clock says is
left. No event loop, no other thread, no task: a reply is read while its caller waits for it.

An async :class:`~aiofins.Client` runs on the driver as on a session: the driver's ``begin``
returns a request already answered (its await returns at once), and its ``call``,
``request`` and ``request_many`` are coroutines that complete without ever suspending, so
the blocking client (:mod:`aiofins.sync`) runs the client's coroutine methods to their end
with one ``send(None)`` each (:func:`run_to_end`), and every method of the client keeps its
checks, plans and decoding.

One call at a time: the driver is not thread-safe; :mod:`aiofins.sync` serialises calls.
"""

from __future__ import annotations

import inspect
import logging
import time
from collections.abc import Callable, Coroutine, Sequence
from typing import Any, NoReturn, TypeVar

from .protocol.errors import CommandError, ConnectionLost, FinsError, FinsTimeout
from .protocol.frames import check_commands
from .protocol.header import FinsAddress
from .session import Response, Session
from .session.breaker import rejection
from .session.clock import Clocks
from .session.messages import no_free_sid, no_response
from .session.response import response_of
from .session.slots import DestState, HeldPending, Pending
from .session.states import LinkState
from .session.watcher import TIMERLESS, Expired
from .transport.blocking import BlockingTransport

R = TypeVar("R")

logger = logging.getLogger("aiofins.session")

#: Seconds between looks for a free SID while all 256 of a destination are taken (each
#: look reads what arrives meanwhile: a late reply frees its SID).
_SID_WAIT = 0.01

#: One command: (MRC, SRC, parameter bytes).
Command = tuple[int, int, bytes]


def run_to_end(coro: Coroutine[Any, Any, R]) -> R:
    """The result of a coroutine that completes without suspending (one of the async
    client's methods over a :class:`BlockingDriver`); a coroutine that does suspend (it
    awaited an event loop's future, event or sleep) is closed and refused with
    :class:`RuntimeError`. (A coroutine already started and suspended once is refused.)"""
    if inspect.getcoroutinestate(coro) == inspect.CORO_CREATED:
        try:
            coro.send(None)
        except StopIteration as done:
            result: R = done.value
            return result
    coro.close()
    raise RuntimeError(
        f"{getattr(coro, '__qualname__', coro)} waited for an event loop: the blocking "
        "driver runs only calls that complete without one"
    )


class _Command:
    """One command of a batch: its request on the wire (``p``), its deadline, the busy end
    codes it met so far."""

    __slots__ = ("busy", "end", "index", "mrc", "p", "params", "src")

    p: HeldPending

    def __init__(self, index: int, command: Command, end: float) -> None:
        self.index = index
        self.mrc, self.src, self.params = command
        self.end = end
        self.busy = 0


class BlockingDriver:
    """Runs the requests of ``session`` over the blocking ``transport`` from the calling
    thread (see the module). What an async :class:`~aiofins.Client` takes as its session:
    ``source``, ``dest``, ``request`` and ``request_many``; anything else is the session's
    (``stats``, ``link_state``, ``breaker_state``, ...)."""

    def __init__(self, session: Session, transport: BlockingTransport) -> None:
        if session.transport is not transport:
            raise CommandError("the driver's transport must be its session's")
        self.session = session
        self.transport = transport
        self.clock = time.monotonic
        # The one clock of the session is the driver's (no event loop to take one from).
        session._use_clock(Clocks(self.clock, self.clock, True))
        # No timer to arm: the driver reads the deadlines itself as it waits.
        session._watcher.at = TIMERLESS
        #: The client's step after its request's reply (:meth:`Session.finish`), bound
        #: here: the client reaches it once per call.
        self.finish: Callable[[Pending, bytes, int], bool] = session.finish

    def __getattr__(self, name: str) -> Any:
        return getattr(self.session, name)

    @property
    def source(self) -> FinsAddress:
        return self.session.source

    @property
    def dest(self) -> FinsAddress:
        return self.session.dest

    @dest.setter
    def dest(self, value: FinsAddress) -> None:
        self.session.dest = value

    # ----------------------------------------------------------------- the link

    def open(self, timeout: float) -> None:
        """Open the link (within ``timeout`` seconds) if it is not open, by the link's
        rules: no attempt while a backoff runs, a failed attempt counted and followed by
        one, the node a FINS/TCP peer assigns adopted."""
        if self.transport.is_open:
            return
        session = self.session
        link = session._link
        link.may_connect()
        link.set_state(LinkState.CONNECTING)
        try:
            self.transport.connect(session, timeout)
            session._adopt_local_node()
        except Exception as exc:
            self.transport.close()
            error = (
                exc
                if isinstance(exc, FinsError)
                else ConnectionLost(
                    f"cannot connect to {self.transport.description}: {exc or type(exc).__name__}"
                )
            )
            link.open_failed(error, exc)
            if error is exc:
                raise
            raise error from exc
        link.opened()

    def interrupt(self) -> None:
        """End a call waiting in another thread with :class:`ConnectionLost` (thread-safe:
        the socket is shut down; :meth:`close` follows once that call has ended)."""
        self.transport.interrupt()

    def close(self) -> None:
        """Close the session (requests still registered fail, their SIDs quarantined) and
        the socket."""
        session = self.session
        if session._link.shut():
            session.fail_all(ConnectionLost(f"session to {self.transport.description} closed"))
        self.transport.close()

    # ----------------------------------------------------------------- one request

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
    ) -> HeldPending | None:
        """:meth:`Session.begin` run to its reply from the calling thread: the request
        (a :class:`HeldPending`) with its reply frame in, so the client's await returns at
        once and its :meth:`~Session.finish` follows; ``None`` when it must wait first (the
        link to open, the breaker, a SID): then :meth:`call`. An error the request ends
        with is raised here, as :meth:`~Session.failure` words it."""
        p: HeldPending | None = self.session.begin(  # type: ignore[assignment]  # (no loop)
            mrc, src, params, dest, timeout, idempotent, retries, cap, in_call, now
        )
        if p is not None:
            self._reply(p, timeout, in_call)
        return p

    def _reply(self, p: HeldPending, timeout: float | None, in_call: bool) -> bytes:
        """``p``'s reply frame, read from the socket while the deadline watcher's rules
        send it again or give it up as its deadlines pass; its failure raised (worded by
        :meth:`Session.failure`: SID quarantined, slot back, breaker told)."""
        session = self.session
        clock = self.clock
        receive = self.transport.receive
        try:
            while (reply := p.result) is None:
                now = clock()
                wait = p.deadline - now
                if wait > 0:
                    receive(wait)
                else:
                    session._watcher.expire(now)
            if type(reply) is not bytes:
                raise reply  # type: ignore[misc]  # (an exception)
        except BaseException as exc:
            raise session.failure(p, exc, timeout, in_call) from None
        return reply

    async def failed(
        self,
        p: HeldPending | None,
        exc: BaseException,
        timeout: float | None = None,
        in_call: bool = False,
    ) -> NoReturn:
        """:meth:`Session.failed` without its turn of an event loop: the error raised."""
        raise self.session.failure(p, exc, timeout, in_call) from None

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
        """:meth:`Session.call` run from the calling thread (completes without
        suspending): a request :meth:`begin` could not start at once (the breaker asked,
        the link opened, a free SID waited for: :meth:`_start`), or, ``after`` a busy
        reply, the command sent again after the session's pauses until the call's
        deadline; each reply through :meth:`~Session.finish`. Returns the reply frame of a
        normal completion."""
        session = self.session
        if dest is None:
            dest = session.dest
        timeout, retries, cap = self._options(timeout, idempotent, retries, cap)
        state = session.dest_state(dest)
        busy = 0
        if after is None:
            now = self.clock()
            end = now + timeout
            breaker = session._breaker
            if breaker.failures and not in_call:  # (turned away: the breaker is told nothing)
                refused = rejection(breaker, session.stats, dest, self.transport.description, now)
                if refused is not None:
                    raise refused
        else:  # (after a busy reply: its call's deadline)
            end = after.end
            time.sleep(session.busy_wait(0))
            busy = 1
        while True:
            try:
                p = self._start(state, mrc, src, params, retries, cap, self.clock(), end, timeout)
            except BaseException as exc:
                raise session.failure(None, exc, timeout, in_call) from None
            frame = self._reply(p, timeout, in_call)
            if session.finish(p, frame, busy):
                return frame
            time.sleep(session.busy_wait(busy))  # busy (2604/2605): again after a pause
            busy += 1

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
    ) -> Response:
        """:meth:`Session.request` (its options, errors, retransmissions, busy retries,
        breaker), run from the calling thread: :meth:`call`'s reply as a response."""
        p = self.begin(mrc, src, params, dest, timeout, idempotent, retries, attempt_timeout)
        if p is not None:
            frame: bytes = p.result  # type: ignore[assignment]  # (begin read the reply)
            if self.session.finish(p, frame):
                return response_of(frame)
        frame = await self.call(
            mrc, src, params, dest, timeout, idempotent, retries, attempt_timeout, after=p
        )
        return response_of(frame)

    def _options(
        self,
        timeout: float | None,
        idempotent: bool,
        retries: int | None,
        attempt_timeout: float | None,
    ) -> tuple[float, int, float | None]:
        """A call's options, the session's where not given (checked as the session does)."""
        session = self.session
        if timeout is None:
            timeout = session.timeout
        elif timeout <= 0:
            raise CommandError(f"timeout {timeout} must be positive")
        if retries is None:
            retries = session.retries if idempotent else 0
        elif retries < 0:
            raise CommandError(f"retries {retries} must not be negative")
        if attempt_timeout is None:
            attempt_timeout = session.attempt_timeout
        elif attempt_timeout <= 0:
            raise CommandError(f"attempt_timeout {attempt_timeout} must be positive")
        return timeout, retries, attempt_timeout

    def _start(
        self,
        state: DestState,
        mrc: int,
        src: int,
        params: bytes,
        retries: int,
        cap: float | None,
        now: float,
        end: float,
        timeout: float,
    ) -> HeldPending:
        """Put a command to ``state``'s destination on the wire and return its request:
        the link opened if it is not, a free SID (waiting for one until the call's ``end``,
        reading the socket meanwhile: a late reply frees its SID), the request registered
        by :meth:`Session.start`, the frame sent. (No in-flight slot is taken: one call
        runs at a time, and a batch keeps to the destination's cap itself.)"""
        session = self.session
        transport = self.transport
        if transport.fast_send is None:  # (set while open)
            self.open(end - now)
            now = self.clock()
        p = HeldPending()
        frame = session.start(p, state, mrc, src, params, retries, now, end, cap)
        while frame is None:  # every SID of the destination taken
            left = end - now
            if left <= 0:
                raise no_free_sid(session.sids, state, timeout)
            transport.receive(min(_SID_WAIT, left))
            now = self.clock()
            frame = session.start(p, state, mrc, src, params, retries, now, end, cap)
        send = transport.fast_send
        try:
            if send is None:
                raise ConnectionLost(f"{transport.description} is closed")
            send(frame)
        except BaseException as exc:  # registered, never sent: given up (SID quarantined)
            session.abandon(p, timeout, isinstance(exc, FinsTimeout))
            raise
        return p

    def _wait(self, p: HeldPending) -> bytes:
        """The reply to ``p``: read from the socket until it comes, ``p`` sent again or
        given up by the deadline watcher's rules as its deadlines pass."""
        receive = self.transport.receive
        clock = self.clock
        expire = self.session._watcher.expire
        while True:
            result = p.result
            if result is not None:
                if isinstance(result, bytes):
                    return result
                raise result
            now = clock()
            wait = p.deadline - now
            if wait > 0:
                receive(wait)
            else:
                expire(now)

    def _pause_or_raise(self, reply: bytes, busy: int, end: float, mrc: int, src: int) -> None:
        """A reply with an error end code: pause before sending the command again if the
        PLC was too busy (:meth:`Session.busy_pause`, ``busy`` retries so far) and the
        call's ``end`` leaves time, else raise the end code's error."""
        session = self.session
        pause = session.busy_pause(reply, busy)
        if pause is not None and pause < end - self.clock():
            session.stats.busy_retries += 1
            time.sleep(pause)
            return
        raise session.end_code_failure(reply, mrc, src)

    def _failed(
        self, exc: BaseException, p: HeldPending | None, dest: FinsAddress, timeout: float
    ) -> BaseException:
        """A call ends with ``exc`` (``p``: its latest request): ``p``, if still in
        flight, given up (its SID quarantined); the breaker told; the error to raise (a
        request that ran out of time words what to check)."""
        session = self.session
        if p is not None:
            session.abandon(p, timeout, isinstance(exc, FinsTimeout))
            if isinstance(exc, Expired):
                exc = no_response(
                    session.transport, session.source, dest, p.mrc, p.src, timeout, p.attempts
                )
        session.tell_breaker(exc, timeout)
        return exc

    # ----------------------------------------------------------------- many requests

    async def request_many(
        self,
        requests: Sequence[Command],
        *,
        dest: FinsAddress | None = None,
        timeout: float | None = None,
        idempotent: bool = False,
        retries: int | None = None,
        window: int | None = None,
        on_response: Callable[[int, Response], object] | None = None,
        on_frame: Callable[[int, bytes], object] | None = None,
    ) -> list[Response]:
        """Send many commands pipelined, up to ``window`` on the wire (default and at
        most: the destination's in-flight cap), as :meth:`Session.request_many` does: each
        with its own ``timeout`` and the guarantees of :meth:`request`, ``on_response(index,
        response)`` as each normal response comes (or ``on_frame(index, frame)``, no
        response made, the list returned empty), the first error raised after the
        others are given up (their SIDs quarantined). Completes without suspending."""
        session = self.session
        if dest is None:
            dest = session.dest
        timeout, retries, cap = self._options(timeout, idempotent, retries, None)
        check_commands(requests)
        if window is not None and window < 1:
            raise CommandError(f"window {window} must be at least 1")
        if not requests:
            return []
        clock = self.clock
        session.log_frames_now()
        if session._breaker.failures:
            refused = rejection(
                session._breaker, session.stats, dest, self.transport.description, clock()
            )
            if refused is not None:
                raise refused
        state = session.dest_state(dest)
        limit = state.slots.limit
        width = min(limit if window is None else min(window, limit), len(requests))
        results: list[Response | None] = [None] * len(requests)
        flight: list[_Command] = []  # in the order sent
        count = len(requests)
        sent = 0  # commands put on the wire so far
        left = count
        current: _Command | None = None  # the command whose step may raise
        try:
            while left:
                while sent < count and len(flight) < width:
                    now = clock()
                    current = _Command(sent, requests[sent], now + timeout)
                    c = current
                    c.p = self._start(
                        state, c.mrc, c.src, c.params, retries, cap, now, c.end, timeout
                    )
                    flight.append(c)
                    sent += 1
                current = next((c for c in flight if c.p.result is not None), None)
                if current is None:
                    self._wait_any(flight)
                    continue
                c = current
                reply = self._wait(c.p)  # its result is in: returned or raised
                if not session.completed(c.p.end_code):  # busy (sent again) or raised
                    self._pause_or_raise(reply, c.busy, c.end, c.mrc, c.src)
                    c.busy += 1
                    c.p = self._start(
                        state, c.mrc, c.src, c.params, retries, cap, clock(), c.end, timeout
                    )
                    continue
                current = None
                flight.remove(c)
                left -= 1
                if on_frame is not None:
                    on_frame(c.index, reply)
                    continue
                response = results[c.index] = response_of(reply)
                if on_response is not None:
                    on_response(c.index, response)
        except BaseException as exc:
            for other in flight:
                if other is not current:
                    session.abandon(other.p, timeout)
            if current is None:
                session.tell_breaker(exc, timeout)
                raise
            # (its request is missing if its first _start() raised)
            raise self._failed(exc, getattr(current, "p", None), dest, timeout) from None
        session.tell_breaker(None, timeout)
        if on_frame is not None:
            return []
        return results  # type: ignore[return-value]  # every one filled

    def _wait_any(self, flight: list[_Command]) -> None:
        """Read the socket until the earliest deadline of ``flight`` (or a frame comes),
        or send again / give up what is due."""
        now = self.clock()
        wait = min(c.p.deadline for c in flight) - now
        if wait > 0:
            self.transport.receive(wait)
        else:
            self.session._watcher.expire(now)
