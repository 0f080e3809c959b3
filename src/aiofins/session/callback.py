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
:func:`start_request`: the same conditions, the same :meth:`Session.start` and receive
path, but no batch: the command's :class:`CallbackPending` hands the reply frame itself to
``done(frame, error)`` (no future, no :class:`Response`), and only a busy end code
(2604/2605) turns it into a :class:`CallbackBatch`, whose retries after a growing pause,
SID waits and extra SID spaces are the batch's.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Protocol

from ..protocol.errors import FinsTimeout
from ..protocol.frames import ERROR_BITS
from ..protocol.header import FinsAddress
from .batch import Batch, Batching, Command
from .breaker import BreakerState
from .messages import no_response
from .response import Response
from .slots import DestState, Pending
from .states import LinkState

logger = logging.getLogger("aiofins.session")

#: ``done(responses, error)``: the responses in command order, or ``None`` and the error.
Done = Callable[[list[Response] | None, BaseException | None], object]
#: ``done(frame, error)`` of :func:`start_request`: the reply frame (its end code a normal
#: completion, possibly with CPU error flags), or ``None`` and the error.
FrameDone = Callable[[bytes | None, BaseException | None], object]


_CLOSED = BreakerState.CLOSED
_OPEN = LinkState.OPEN


class Calling(Batching, Protocol):
    """What :func:`start_requests` uses of the session (a :class:`~aiofins.session.Session`)
    besides what its batch does: whether the call may start at once."""

    @property
    def link_state(self) -> LinkState: ...

    @property
    def breaker_state(self) -> BreakerState: ...


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
    """One command of :func:`start_request` on the wire: the receive path hands its reply
    to :meth:`wake`, the deadline watcher its timeout (or the link its failure) to
    :meth:`fail`, and either calls ``done`` from there. Made bare, ``CallbackPending()``
    (its ``__init__`` sets nothing): :func:`start_request` and :meth:`Session.start` set
    every field."""

    __slots__ = ("done_with", "handle", "params", "retries", "session", "target", "timeout")

    def __init__(self) -> None:
        pass

    session: Calling
    #: The destination's state (address, slots).
    target: DestState
    timeout: float
    params: bytes
    retries: int
    done_with: FrameDone | None
    #: The batch that took over after a busy end code (see :meth:`wake`), if any.
    handle: CallbackBatch | None

    def wake(self, frame: bytes) -> None:
        """The reply (out of the pending table, its SID lingering): a normal completion is
        counted and handed over; a busy end code (2604/2605) hands the command to a
        :class:`CallbackBatch` that sends it again after the session's pause; any other
        end code fails the call with the session's exception for it."""
        done = self.done_with
        if done is None:  # cancelled
            return
        session = self.session
        end = self.end_code
        if not end & ERROR_BITS:
            if end:  # CPU error flags: logged and counted by the session's own step
                session.response(frame, end)
            else:
                session.stats.completed += 1
            self.done_with = None
            slots = self.slots  # free_slot(), inlined (a call saved per reply)
            if slots is not None:
                self.slots = None
                slots.release()
            session.tell_breaker(None, self.timeout)
            try:
                done(frame, None)
            except Exception:  # the caller's bug: logged here, never raised into the transport
                logger.exception("%s: a request's callback failed", session.transport.description)
            return
        pause = session.busy_pause(frame, 0)
        if pause is not None:
            self.handle = _busy_batch(self, pause)
            return
        self._end(session.end_code_failure(frame, self.mrc, self.src))

    def fail(self, exc: BaseException) -> None:
        """No reply after every transmission (its SID quarantined and slot freed by the
        watcher), or the link failed."""
        if self.done_with is None:
            return
        if isinstance(exc, FinsTimeout):
            s = self.session
            exc = no_response(
                s.transport, s.source, self.target.address, self.mrc, self.src, self.timeout,
                self.attempts,
            )  # fmt: skip
        self._end(exc)

    def _end(self, error: BaseException) -> None:
        done = self.done_with
        assert done is not None
        self.done_with = None
        self.free_slot()
        self.session.tell_breaker(error, self.timeout)
        _call(self.session, done, None, error)

    def cancel(self) -> None:
        """Give up without calling ``done``: unanswered, its SID is quarantined; the slot
        given back. (Nothing if it has ended.)"""
        if self.done_with is None:
            return
        self.done_with = None
        batch = self.handle
        if batch is not None:
            batch.cancel()
            return
        self.session.abandon(self, self.timeout)
        self.free_slot()


def _call(
    session: Calling, done: FrameDone, frame: bytes | None, error: BaseException | None
) -> None:
    try:
        done(frame, error)
    except Exception:  # the caller's bug: logged here, never raised into the transport
        logger.exception("%s: a request's callback failed", session.transport.description)


def _busy_batch(p: CallbackPending, pause: float) -> CallbackBatch:
    """A busy end code came for ``p``: a one-command :class:`CallbackBatch` holding ``p``'s
    slot sends it again after ``pause`` (its next busy replies pause longer, as in any
    batch), and hands the outcome to ``p``'s ``done``."""
    session = p.session
    session.stats.busy_retries += 1
    done = p.done_with
    assert done is not None

    def ended(responses: list[Response] | None, error: BaseException | None) -> None:
        p.done_with = None
        done(None if responses is None else responses[0].frame, error)

    command: Command = (p.mrc, p.src, p.params)
    batch = CallbackBatch(session, (command,), p.target, p.timeout, p.retries, 1)
    batch.done = ended
    batch.starting = False
    batch.held = 1  # p's slot
    p.slots = None
    batch.next = batch.started = 1  # (sent by later(), not by a flush)
    batch.busy[0] = 1
    batch.later(pause, 0)
    return batch


def start_request(
    session: Calling,
    command: Command,
    done: FrameDone,
    *,
    dest: FinsAddress | None = None,
    timeout: float | None = None,
    retries: int | None = None,
) -> CallbackPending | None:
    """Send one idempotent ``command`` (``(mrc, src, params)``, checked by the caller) and
    call ``done(frame, error)`` with its reply frame or its failure; the returned request's
    :meth:`~CallbackPending.cancel` gives up on it. ``None`` (nothing sent) when it cannot
    start at once, as :func:`start_requests`, or when every SID of the destination is
    taken (the awaitable path waits for one)."""
    if (
        not session.on_asyncio
        or session.link_state is not _OPEN
        or session.breaker_state is not _CLOSED
    ):
        return None
    send = session.transport.fast_send
    if send is None:
        return None
    state = session.dest_state(session.dest if dest is None else dest)
    slots = state.slots
    if not slots.try_acquire():
        return None
    if timeout is None:
        timeout = session.timeout
    if retries is None:
        retries = session.retries
    p = CallbackPending()
    p.fut = None
    p.session = session
    p.target = state
    p.timeout = timeout
    p.handle = None
    p.params = command[2]
    p.retries = retries
    session.log_frames_now()
    now = session.clock()
    try:
        frame = session.start(p, state, *command, retries, now, now + timeout, None)
    except BaseException:
        slots.release()
        raise
    if frame is None:  # no free SID of the session's own: the awaitable path waits
        slots.release()
        return None
    p.slots = slots
    p.done_with = done
    try:
        send(frame)
    except Exception:  # the send failed: nothing of it left; the awaitable path says why
        p.done_with = None
        session.abandon(p, timeout)
        p.free_slot()
        return None
    return p
