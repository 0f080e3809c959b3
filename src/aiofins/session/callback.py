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
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from ..protocol.header import FinsAddress
from .batch import Batch, Command
from .breaker import BreakerState
from .core import Session
from .response import Response
from .states import LinkState

logger = logging.getLogger("aiofins.session")

#: ``done(responses, error)``: the responses in command order, or ``None`` and the error.
Done = Callable[[list[Response] | None, BaseException | None], object]


_CLOSED = BreakerState.CLOSED
_OPEN = LinkState.OPEN


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
    session: Session,
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
