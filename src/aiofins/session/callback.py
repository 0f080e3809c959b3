"""Requests whose outcome is handed to a callback (asyncio): no task waits for the reply.

A caller that sends a few commands on a timer, such as the Poller's one timer sending every
due scan, would otherwise pay a task wake-up per request (the task sleeps, wakes, awaits a
future, wakes again). :func:`start_requests` sends the commands from the caller's own step
as a :class:`~aiofins.session.batch.Batch` and calls ``done(responses, error)`` from the
receive callback (or the deadline watcher, or the link's failure) when the batch ends.

Everything of :meth:`Session.request_many` holds, as the batch is the same: SID matching,
lingering and quarantine, the destination's in-flight cap, the one deadline structure,
retransmission of idempotent commands with the same frame and SID, busy end codes (2604,
2605) retried after a growing pause, SID waits and extra SID spaces, the request hooks and
the session's counters; the circuit breaker learns each outcome as from a call.

It starts only when it can at once: under asyncio, with a transport that sends
synchronously and a link that is open, the breaker closed and a slot of the destination
free. Otherwise :func:`start_requests` returns ``None`` and the caller takes the awaitable
path (:meth:`Session.request_many`), which waits for the link, the slot or the breaker's
probe as any call does.

A caller of one command a time (a Poller's scan of one frame) takes
:func:`start_request`: the session's request path itself, :meth:`Session.begin` with the
caller's own record (a :class:`CallbackPending`), whose ``wake``/``fail`` call
:meth:`Session.finish` / :meth:`Session.failure` from the receive path or the watcher and
hand the reply frame itself to ``done(frame, error)`` (no future, no batch, no
:class:`Response`); a busy end code sends it again from a timer after the session's pause.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Protocol

from ..protocol.header import FinsAddress
from .batch import Batch, Batching, Command
from .breaker import BreakerState
from .response import Response
from .slots import Pending
from .states import LinkState

logger = logging.getLogger("aiofins.session")

#: ``done(responses, error)``: the responses in command order, or ``None`` and the error.
Done = Callable[[list[Response] | None, BaseException | None], object]
#: ``done(frame, error)`` of :func:`start_request`: the reply frame (its end code a normal
#: completion, possibly with CPU error flags), or ``None`` and the error.
FrameDone = Callable[[bytes | None, BaseException | None], object]


_CLOSED = BreakerState.CLOSED
_OPEN = LinkState.OPEN

#: Seconds between tries to send a command again after a busy reply's pause when the
#: request path cannot start it at once (no slot or SID free, the link, the breaker).
_AGAIN = 0.01


class Calling(Batching, Protocol):
    """What :func:`start_requests` uses of the session (a :class:`~aiofins.session.Session`)
    besides what its batch does: whether the call may start at once."""

    @property
    def link_state(self) -> LinkState: ...

    @property
    def breaker_state(self) -> BreakerState: ...

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
    ) -> Pending | None: ...

    def finish(self, p: Pending, frame: bytes, busy: int = 0) -> bool: ...

    def failure(
        self,
        p: Pending | None,
        exc: BaseException,
        timeout: float | None = None,
        in_call: bool = False,
    ) -> BaseException: ...

    def busy_wait(self, busy: int) -> float: ...


class Cancellable(Protocol):
    """A timer's handle (asyncio's or uvloop's ``TimerHandle``)."""

    def cancel(self) -> None: ...


class CallbackBatch(Batch):
    """A batch whose end calls ``done`` instead of waking an awaiting task.

    Ended while it is being started (its first send failed), it calls ``done`` from the
    event loop's next step: the caller of :func:`start_requests` has its handle first.
    """

    __slots__ = ("done", "starting")

    done: Done | None
    starting: bool

    def finish(self, error: BaseException | None) -> None:
        if self.fut.done():
            return
        self.error = error
        self.fut.set_result(None)  # (awaited by nobody: every check of the batch reads it)
        if self.starting:
            self.session.loop.call_soon(self._ended)
        else:
            self._ended()

    def _ended(self) -> None:
        """Clean up (SIDs of unanswered commands quarantined, slots freed), tell the breaker,
        then the caller."""
        done = self.done
        if done is None:  # cancelled
            return
        self.done = None
        self.cleanup()
        error = self.error
        self.session.tell_breaker(error, self.timeout)
        if error is None:
            results: list[Response] = self.results  # type: ignore[assignment]  # all filled
            self._call(done, results, None)
        else:
            self._call(done, None, error)

    def _call(
        self, done: Done, results: list[Response] | None, error: BaseException | None
    ) -> None:
        try:
            done(results, error)
        except Exception:  # the caller's bug: logged here, never raised into the transport
            logger.exception("%s: a request's callback failed", self.session.transport.description)

    def cancel(self) -> None:
        """Give up without calling ``done``: unanswered commands' SIDs are quarantined,
        the slots given back. (Nothing if the batch has ended.)"""
        if self.done is None:
            return
        self.done = None
        self.cleanup()


def start_requests(
    session: Calling,
    commands: Sequence[Command],
    done: Done,
    *,
    dest: FinsAddress | None = None,
    timeout: float | None = None,
    retries: int | None = None,
) -> CallbackBatch | None:
    """Send idempotent ``commands`` (``(mrc, src, params)``, checked by the caller)
    pipelined and call ``done(responses, error)`` when they are all answered or the first
    fails; the returned batch's :meth:`~CallbackBatch.cancel` gives up on them.

    ``timeout`` and ``retries`` as in :meth:`Session.request_many` (default: the session's).
    ``None`` (nothing sent) when it cannot start at once: not under asyncio, no synchronous
    send, the link not open, the breaker not closed, or no slot of ``dest`` free.
    """
    if (
        not session.on_asyncio
        or session.transport.fast_send is None
        or session.link_state is not _OPEN
        or session.breaker_state is not _CLOSED
        or not commands
    ):
        return None
    state = session.dest_state(session.dest if dest is None else dest)
    slots = state.slots
    if not slots.try_acquire():
        return None
    width = min(slots.limit, len(commands))
    batch = CallbackBatch(
        session,
        commands,
        state,
        session.timeout if timeout is None else timeout,
        session.retries if retries is None else retries,
        width,
    )
    batch.done = done
    batch.held = 1
    batch.starting = True
    try:
        batch.start()
    except BaseException:
        batch.cancel()
        raise
    finally:
        batch.starting = False
    return batch


class CallbackPending(Pending):
    """One command of a :class:`PreparedRequest` on the wire, on the session's request
    path: :meth:`Session.begin` sends it; the receive path hands its reply to :meth:`wake`,
    which calls :meth:`Session.finish`, the deadline watcher its timeout (or the link its
    failure) to :meth:`fail`, which calls :meth:`Session.failure`; either calls ``done``
    from there. A busy reply (2604/2605) with time left sends it again from a timer after
    the session's pause (:meth:`again`). Made bare, ``CallbackPending()`` (its ``__init__`` sets
    nothing): :meth:`PreparedRequest.send` and :meth:`Session.begin` set every field."""

    __slots__ = ("busy", "busy_reply", "done_with", "handle", "prep")

    def __init__(self) -> None:
        pass

    #: What it sends, to whom, with which options (shared by every send of the command).
    prep: PreparedRequest
    #: Busy replies so far, and the last of them.
    busy: int
    busy_reply: bytes
    done_with: FrameDone | None
    #: The timer that sends it again after a busy reply, while one is due (the event
    #: loop's handle: asyncio's or uvloop's, hence a protocol).
    handle: Cancellable | None

    def wake(self, frame: bytes) -> None:
        """The reply (out of the pending table, its SID lingering), through the session's
        :meth:`~Session.finish`: a normal completion handed over; a busy one with time
        left sent again after the session's pause; any other end code fails the call with
        the session's exception for it."""
        done = self.done_with
        if done is None:  # cancelled
            return
        session = self.prep.session
        try:
            if not session.finish(self, frame, self.busy):  # busy: again after a pause
                self.busy_reply = frame
                self.handle = session.loop.call_later(session.busy_wait(self.busy), self.again)
                self.busy += 1
                return
        except Exception as exc:  # (the end code's error)
            self._end(None, exc)
            return
        self.done_with = None
        try:
            done(frame, None)
        except Exception:  # the caller's bug: logged here, never raised into the transport
            logger.exception("%s: a request's callback failed", session.transport.description)

    def fail(self, exc: BaseException) -> None:
        """No reply after every transmission (its SID quarantined and slot freed by the
        watcher), or the link failed: :meth:`Session.failure` words it."""
        if self.done_with is not None:
            self._end(None, self.prep.session.failure(self, exc, self.prep.timeout))

    def again(self) -> None:
        """After a busy reply's pause: the command sent again on the request path, within
        the call's deadline; if it cannot start at once (no slot or SID free, the link or
        the breaker), tried again shortly, and the PLC's busy reply is the error at the
        deadline."""
        self.handle = None
        if self.done_with is None:
            return
        prep = self.prep
        session = prep.session
        left = self.end - session.clock()
        if left > 0.0:
            try:
                p = session.begin(
                    self.mrc, self.src, prep.params, prep.dest, left, True, prep.retries,
                    pending=self,
                )  # fmt: skip
            except Exception as exc:
                self._end(None, exc)
                return
            if p is None:
                self.handle = session.loop.call_later(min(_AGAIN, left), self.again)
            return
        self._end(None, session.end_code_failure(self.busy_reply, self.mrc, self.src))

    def _end(self, frame: bytes | None, error: BaseException | None) -> None:
        done = self.done_with
        assert done is not None
        self.done_with = None
        _call(self.prep.session, done, frame, error)

    def cancel(self) -> None:
        """Give up without calling ``done``: unanswered, its SID is quarantined; the slot
        given back. (Nothing if it has ended.)"""
        if self.done_with is None:
            return
        self.done_with = None
        handle = self.handle
        if handle is not None:
            self.handle = None
            handle.cancel()
            return
        session = self.prep.session
        timeout = self.prep.timeout
        session.abandon(self, session.timeout if timeout is None else timeout)
        self.free_slot()


def _call(
    session: Calling, done: FrameDone, frame: bytes | None, error: BaseException | None
) -> None:
    try:
        done(frame, error)
    except Exception:  # the caller's bug: logged here, never raised into the transport
        logger.exception("%s: a request's callback failed", session.transport.description)


class PreparedRequest:
    """One idempotent command (``(mrc, src, params)``) to send again and again, its reply
    frame or failure handed to ``done(frame, error)``: made once (a Poller's scan of one
    frame makes it once per plan and session), then each :meth:`send` is the session's
    request path, :meth:`Session.begin` with a new :class:`CallbackPending`, which holds
    this request instead of a copy of its options. ``dest``, ``timeout`` and ``retries``
    as in :func:`start_request`; the command is checked by each send, as every request is."""

    __slots__ = ("dest", "done", "mrc", "params", "retries", "session", "src", "timeout")

    def __init__(
        self,
        session: Calling,
        command: Command,
        done: FrameDone,
        *,
        dest: FinsAddress | None = None,
        timeout: float | None = None,
        retries: int | None = None,
    ) -> None:
        self.session = session
        self.mrc, self.src, self.params = command
        self.done = done
        self.dest = dest
        self.timeout = timeout
        self.retries = retries

    def send(self) -> CallbackPending | None:
        """Send it now and call ``done`` when it ends; the request on the wire (its
        :meth:`~CallbackPending.cancel` gives up on it), or ``None`` (nothing sent) when
        :meth:`~Session.begin` cannot start it at once (the link, the breaker, no slot or
        SID free: the awaitable path waits), or not under asyncio."""
        session = self.session
        if not session.on_asyncio:
            return None
        p = CallbackPending()
        p.fut = None
        p.prep = self
        p.handle = None
        p.busy = 0
        p.done_with = self.done
        begin = session.begin(
            self.mrc, self.src, self.params, self.dest, self.timeout, True, self.retries,
            pending=p,
        )  # fmt: skip
        if begin is None:
            p.done_with = None
            return None
        return p


def start_request(
    session: Calling,
    command: Command,
    done: FrameDone,
    *,
    dest: FinsAddress | None = None,
    timeout: float | None = None,
    retries: int | None = None,
) -> CallbackPending | None:
    """Send one idempotent ``command`` (``(mrc, src, params)``) on the session's request
    path (:meth:`Session.begin` with this request's record) and call ``done(frame,
    error)`` with its reply frame or its failure; the returned request's
    :meth:`~CallbackPending.cancel` gives up on it. ``None`` (nothing sent) when
    :meth:`~Session.begin` cannot start it at once (the link, the breaker, no slot or SID
    free: the awaitable path waits), or not under asyncio. (A command sent again and
    again: :class:`PreparedRequest`.)"""
    return PreparedRequest(
        session, command, done, dest=dest, timeout=timeout, retries=retries
    ).send()
