"""Pipelined bulk requests: many commands from one caller, one wake-up for the whole batch.

Under asyncio with a transport that sends synchronously (``fast_send``), the batch keeps up
to ``window`` requests on the wire. Each reply is handled in the session's receive callback,
which stores the result and sends the batch's next command in the same step; the caller
awaits one future that resolves when every result is in or the first error occurs. Under
other backends (trio) the batch runs as ``window`` concurrent :meth:`Session.request` loops.

Every guarantee of ``request`` holds per command: SIDs are allocated and quarantined the same
way, the destination's in-flight cap bounds the window, deadlines sit in the session's one
deadline structure, idempotent commands are retransmitted by the session with the same
frame and SID, busy end
codes (2604/2605) are retried after the same growing pause, other end codes raise the same
exceptions. The first error cancels the rest: their SIDs are quarantined, their slots freed.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from typing import Any, NoReturn, Protocol, cast

import anyio
import anyio.lowlevel

from ..protocol.endcodes import EndCode
from ..protocol.errors import (
    CommandError,
    ConnectionLost,
    FinsError,
    FinsTimeout,
)
from ..protocol.frames import check_command, check_commands, end_code_error
from ..protocol.header import FinsAddress
from .messages import no_free_sid, no_response
from .options import shown
from .response import Response, _new, _set_data, _set_end_code, _set_frame
from .sids import may_send_again
from .slots import DestState, Pending
from .spaces import ExtraSpace, SidUser

_NORMAL = EndCode(0)
_DEBUG = logging.DEBUG
logger = logging.getLogger("aiofins.session")
#: Pause before trying again when all 256 SIDs of the destination are busy or quarantined.
_SID_WAIT = 0.01

#: One command of a batch: (MRC, SRC, parameter bytes).
Command = tuple[int, int, bytes]
#: ``on_response(index, response)``: called as each command's normal response arrives.
OnResponse = Callable[[int, Response], object]
#: ``on_frame(index, frame)``: each command's normal reply frame as it arrives, instead of a
#: :class:`Response` (the caller decodes the frame: ``frame[14:]`` is the data).
OnFrame = Callable[[int, bytes], object]

__all__ = ["check_command", "end_code_error", "raise_after_a_turn", "request_many"]


class Batching(SidUser, Protocol):
    """What a batch uses of its session (a :class:`~aiofins.session.Session`): the request
    path's steps, its settings and counters (besides a SID waiter's: :class:`SidUser`,
    whose :meth:`~SidUser.start` and :meth:`~SidUser.abandon` it takes too)."""

    @property
    def dest(self) -> FinsAddress: ...

    @property
    def retries(self) -> int: ...

    @property
    def loop(self) -> Any: ...

    @property
    def on_asyncio(self) -> bool: ...

    def log_frames_now(self) -> None: ...

    def start_burst(
        self,
        ps: list[Pending],
        commands: list[Command],
        state: DestState,
        retries: int,
        now: float,
        end: float,
    ) -> list[bytes]: ...

    def drop_answered(self) -> None: ...

    async def ensure_open(self, timeout: float | None = None) -> None: ...

    def dest_state(self, dest: FinsAddress) -> DestState: ...

    def spare_sid(self, state: DestState, now: float) -> tuple[int, ExtraSpace] | None: ...

    def completed(self, end_code: int) -> bool: ...

    def busy_pause(self, frame: bytes, busy: int) -> float | None: ...

    def end_code_failure(self, frame: bytes, mrc: int, src: int) -> FinsError: ...

    def requests_in_flight(self) -> list[Pending]: ...

    def tell_breaker(self, error: BaseException | None, timeout: float) -> None: ...

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
    ) -> Response: ...


async def raise_after_a_turn(exc: ConnectionLost) -> NoReturn:
    """Raise ``exc`` after yielding to the event loop once.

    A :class:`ConnectionLost` is often raised without any wait (the reconnect backoff, a send
    on a link whose end the transport has not yet been told of): the yield lets a caller that
    retries in a loop with no pause of its own leave the loop running, the transport's news
    among it. The error may be shared by other callers, who re-raise it meanwhile: it is
    raised with the traceback it has now.
    """
    traceback = exc.__traceback__
    await anyio.lowlevel.cancel_shielded_checkpoint()
    raise exc.with_traceback(traceback)


class BatchPending(Pending):
    """One command of a batch on the wire; the receive callback hands its reply to the batch.

    Made bare, ``BatchPending()`` (no ``__init__`` in its classes: no Python call per
    command): :meth:`Batch.flush` sets the batch's fields, :meth:`Session.start` the rest."""

    __slots__ = ("batch", "index")

    batch: Batch
    index: int

    def wake(self, frame: bytes) -> None:
        """The receive callback matched a reply to this command (already out of the pending
        table): hand its frame to the caller (``on_frame``) or store its :class:`Response`,
        and let the slot carry the batch's next command, or end the batch. (Here rather
        than in a method of the batch: one call less per reply.)"""
        batch = self.batch
        if batch.fut.done():
            return
        session = batch.session
        end_code = self.end_code
        if not end_code:  # 0000, the usual reply: counted as Session.completed counts it
            session.stats.completed += 1
        elif not session.completed(end_code):  # an error: busy (sent again) or raised
            batch.refused(self, frame)
            return
        try:
            if (on_frame := batch.on_frame) is not None:  # the caller decodes the frame
                on_frame(self.index, frame)
            else:  # (response_of(), inlined, its end code read once: this runs per reply)
                response: Response = _new(Response)
                _set_end_code(response, EndCode(end_code) if end_code else _NORMAL)
                _set_data(response, frame[14:])
                _set_frame(response, frame)
                batch.results[self.index] = response
                if batch.on_response is not None:
                    batch.on_response(self.index, response)
        except BaseException as exc:  # the caller's: raised to it, not to the transport
            batch.finish(exc)
            return
        remaining = batch.remaining = batch.remaining - 1
        if not remaining:
            batch.finish(None)
            return
        following = batch.next
        if following < batch.count and batch.held >= batch.window and not batch.state.slots.waiters:
            batch.next = following + 1  # the common case of slot_free, inlined
            if batch.flush_handle is None:
                batch.flush_handle = session.loop.call_soon(batch.flush)
        else:
            batch.slot_free()

    def fail(self, exc: BaseException) -> None:
        self.batch.failed(self, exc)


class Batch:
    """The state of one :func:`request_many` call on the asyncio fast path.

    Commands go out in bursts: a slot freed by a reply in the receive callback only moves
    :attr:`next` on; at the end of that event-loop step :meth:`flush` starts (SID, frame,
    registration, deadline: :meth:`Session.start`) and sends every command the step freed
    a slot for, together: the peer gets a burst instead of a wake-up per frame, and what
    is the same for the whole burst (the clock, the transport, the logging level) is
    looked up once."""

    __slots__ = (
        "again",
        "busy",
        "commands",
        "count",
        "dest",
        "error",
        "flush_handle",
        "fut",
        "handles",
        "held",
        "idempotent",
        "keep",
        "next",
        "on_frame",
        "on_response",
        "remaining",
        "results",
        "retries",
        "session",
        "sid_waits",
        "started",
        "state",
        "timeout",
        "window",
    )

    def __init__(
        self,
        session: Batching,
        commands: Sequence[Command],
        state: DestState,
        timeout: float,
        retries: int,
        window: int,
        on_response: OnResponse | None = None,
        idempotent: bool = False,
        on_frame: OnFrame | None = None,
    ) -> None:
        self.session = session
        self.on_response = on_response
        #: Given: each normal reply frame is handed to it, no :class:`Response` kept.
        self.on_frame = on_frame
        #: Commands sent without retries: on a link that has shown duplicates each that
        #: may be sent again (idempotent, or a read: :func:`~.sids.may_send_again`) keeps
        #: its frame (see ``Session._keep_frame``).
        self.keep = not retries
        self.idempotent = idempotent
        self.commands = commands
        self.count = len(commands)
        self.state = state
        self.dest = state.address
        self.timeout = timeout
        self.retries = retries
        self.window = window
        self.results: list[Response | None] = [None] * len(commands)
        self.remaining = len(commands)
        self.next = 0  # commands given a slot: the next one not yet given one
        self.started = 0  # commands started (sent): those up to next start in the next flush
        self.held = 0  # slots of the destination this batch holds
        #: Commands to start again in the next flush (busy, or after waiting for a SID).
        self.again: list[int] = []
        #: Command index -> busy end codes (2604/2605) it got so far.
        self.busy: dict[int, int] = {}
        self.handles: set[asyncio.TimerHandle] = set()
        #: Command index -> when it first found no free SID (it gives up after ``timeout``).
        self.sid_waits: dict[int, float] = {}
        self.error: BaseException | None = None
        self.flush_handle: asyncio.Handle | None = None
        self.fut: asyncio.Future[None] = session.loop.create_future()

    # -- sending ------------------------------------------------------------------------

    def flush(self) -> None:
        """Start and send every command due: those a slot was freed for since the last
        flush, and those to send again. One burst: the clock is read and the logging level
        asked once for all of it (see :meth:`Session.log_frames_now`); each command is
        started (the request hooks and the frame's log run then) and the burst sent."""
        self.flush_handle = None
        session = self.session
        session.drop_answered()  # (the replies since the last burst left it to this)
        first, last = self.started, self.next
        again = self.again
        if (first == last and not again) or self.fut.done():
            return
        self.started = last
        if again:
            self.again = []
            due: Sequence[int] = [*again, *range(first, last)]
        else:
            due = range(first, last)
        session.log_frames_now()
        commands, state, retries = self.commands, self.state, self.retries
        now = session.clock()
        end = now + self.timeout
        ps: list[Pending] = []
        mine: list[Command] = []
        for index in due:
            p = BatchPending()  # session.start_burst() sets the fields of every request
            p.fut = None
            p.slots = None  # the batch holds its slots (see held)
            p.batch = self
            p.index = index
            ps.append(p)
            mine.append(commands[index])
        frames = session.start_burst(ps, mine, state, retries, now, end)
        if len(frames) < len(ps) or self.sid_waits or (self.keep and session.sids.linger):
            self.started_each(ps, frames, now, end)
        if not frames:
            return
        transport = session.transport
        try:
            send_many = transport.fast_send_many
            if send_many is not None:  # one write for all (FINS/TCP)
                send_many(frames)
                return
            fast_send = transport.fast_send
            if fast_send is None:
                raise ConnectionLost(f"{transport.description} is closed")
            for frame in frames:
                fast_send(frame)
        except BaseException as exc:  # (cleanup() gives up what this batch has in flight)
            self.finish(exc)

    def started_each(self, ps: list[Pending], frames: list[bytes], now: float, end: float) -> None:
        """After :meth:`Session.start_burst <aiofins.session.Session.start_burst>` started
        the first ``len(frames)`` of ``ps`` (sent ``now``, until ``end``): what the unusual
        cases need per command. Each of those kept its frame where the duplicate rule needs
        it (see ``Session._keep_frame``) and stopped waiting for a SID; the rest are
        started one by one (:meth:`Session.start`), those finding no free SID of the
        transport's own going to :meth:`sid_elsewhere`."""
        session = self.session
        keep = self.keep and session.sids.linger
        sid_waits = self.sid_waits
        started = len(frames)
        for i, made in enumerate(ps):
            p = cast(BatchPending, made)  # (flush made each: list[Pending] for start_burst)
            mrc, src, params = self.commands[p.index]
            if i < started:
                frame = frames[i]
            else:
                got = session.start(p, self.state, mrc, src, params, self.retries, now, end, None)
                if got is None:  # no free SID of the transport's own
                    self.sid_elsewhere(p, now, end)
                    continue
                frame = got
                frames.append(frame)
            if keep and may_send_again(self.idempotent, mrc, src, params):
                p.plan = (frame, 0, end, None, end - now)  # (Session._keep_frame)
            if sid_waits:
                sid_waits.pop(p.index, None)

    def sid_elsewhere(self, p: BatchPending, now: float, end: float) -> None:
        """Command ``p.index`` found every SID of the transport's own taken: sent at once on
        an extra SID space that has one (another is opened meanwhile if none has), else
        tried again shortly (every :data:`_SID_WAIT`, the last time at its deadline),
        keeping its slot, at most until the batch's ``timeout`` after its first try."""
        session = self.session
        state = self.state
        index = p.index
        got = session.spare_sid(state, now)
        if got is not None:
            key, space = got
            space.dest_state(state).cursor = key & 0xFF
            mrc, src, params = self.commands[index]
            frame = session.start(p, state, mrc, src, params, self.retries, now, end, None, space)
            assert frame is not None
            if (
                self.keep
                and space.sids.linger
                and may_send_again(self.idempotent, mrc, src, params)
            ):
                p.plan = (frame, 0, end, None, end - now)  # (Session._keep_frame)
            self.sid_waits.pop(index, None)
            self.send_on(space, p, frame)
            return
        since = self.sid_waits.setdefault(index, now)
        if index == self.next - 1 or len(self.sid_waits) == 1:
            session.stats.sid_exhausted += 1
        left = since + self.timeout - now
        if left <= 0.0:
            self.finish(no_free_sid(session.sids, state, self.timeout))
            return
        # The last look is at the deadline itself, not at the first SID_WAIT past it.
        self.later(min(_SID_WAIT, left), index)

    def send_on(self, space: ExtraSpace, p: BatchPending, frame: bytes) -> None:
        """Send ``p`` at once on an extra SID space's own transport."""
        try:
            fast_send = space.transport.fast_send
            if fast_send is None:
                raise ConnectionLost(f"{space.transport.description} is closed")
            fast_send(frame)
        except BaseException as exc:
            self.abandon(p)
            self.finish(exc)

    def send(self, index: int) -> None:
        """Start and send command ``index`` again (on the slot this batch holds for it)."""
        self.again.append(index)
        if self.flush_handle is None:
            self.flush()

    def later(self, delay: float, index: int) -> None:
        """:meth:`send` command ``index`` again after ``delay`` seconds."""
        handle: asyncio.TimerHandle

        def fire() -> None:
            self.handles.discard(handle)
            self.send(index)

        handle = self.session.loop.call_later(delay, fire)
        self.handles.add(handle)

    def start(self) -> None:
        """Send the first commands on the slots held (the caller holds at least one)."""
        slots = self.state.slots
        while self.held < self.window and slots.try_acquire():
            self.held += 1
        self.next = max(self.next, min(self.held, self.count))
        self.flush()

    def slot_free(self) -> None:
        """A command of this batch completed: its slot goes to the next command, if any
        (started in the next flush).

        Other callers waiting for the destination get the slot first (keeping one for the
        batch); otherwise free slots are taken up to the window.
        """
        slots = self.state.slots
        n = self.count
        if self.next < n and not (slots.waiters and self.held > 1):
            self.next += 1  # the freed slot carries the next command
            while self.held < self.window and self.next < n and slots.try_acquire():
                self.held += 1
                self.next += 1
            if self.flush_handle is None:
                self.flush_handle = self.session.loop.call_soon(self.flush)
        else:
            self.held -= 1
            slots.release()  # to the first waiter of the destination, if any

    # -- receiving ----------------------------------------------------------------------

    def refused(self, p: BatchPending, frame: bytes) -> None:
        """``p``'s reply has an error end code: sent again after a pause if the PLC was
        busy (2604/2605) and busy retries are left, else the batch ends with its error."""
        session = self.session
        index = p.index
        busy = self.busy.get(index, 0)
        pause = session.busy_pause(frame, busy)
        if pause is not None:
            session.stats.busy_retries += 1
            self.busy[index] = busy + 1
            self.later(pause, index)
            return
        self.finish(session.end_code_failure(frame, p.mrc, p.src))

    def failed(self, p: BatchPending, exc: BaseException) -> None:
        """``p`` timed out after every transmission (already quarantined) or the link failed."""
        if self.fut.done():
            return
        if isinstance(exc, FinsTimeout):
            s = self.session
            exc = no_response(
                s.transport, s.source, self.dest, p.mrc, p.src, self.timeout, p.attempts
            )
        self.finish(exc)

    # -- ending -------------------------------------------------------------------------

    def finish(self, error: BaseException | None) -> None:
        if not self.fut.done():
            self.error = error
            self.fut.set_result(None)

    def abandon(self, p: BatchPending) -> None:
        """Give up on ``p``: out of the pending table, its SID quarantined."""
        self.session.abandon(p, self.timeout)

    def cleanup(self) -> None:
        """After the caller resumed (done, failed or cancelled): nothing of the batch left."""
        if not self.fut.done():
            self.fut.cancel()
        for handle in self.handles:
            handle.cancel()
        self.handles.clear()
        if self.flush_handle is not None:
            self.flush_handle.cancel()
            self.flush_handle = None
        self.again.clear()
        if self.remaining:  # (all answered: none of them is in the pending table)
            # Sent and not answered: this batch's entries of the pending table (a scan, once).
            mine = [
                p
                for p in self.session.requests_in_flight()
                if isinstance(p, BatchPending) and p.batch is self
            ]
            for p in mine:
                self.abandon(p)
        slots = self.state.slots
        while self.held:
            self.held -= 1
            slots.release()
        self.session.drop_answered()  # (what the replies left to a next burst)


async def request_many(
    session: Batching,
    commands: Sequence[Command],
    *,
    dest: FinsAddress | None,
    timeout: float | None,
    idempotent: bool,
    retries: int | None,
    window: int | None,
    on_response: OnResponse | None = None,
    on_frame: OnFrame | None = None,
) -> list[Response]:
    """See :meth:`Session.request_many` (with ``on_frame`` the list is empty)."""
    timeout, retries = _options(session, commands, timeout, idempotent, retries, window)
    if dest is None:
        dest = session.dest
    if not commands:
        return []
    transport = session.transport
    if transport.fast_send is None and not transport.is_open:
        try:
            await session.ensure_open(timeout)
        except ConnectionLost as exc:
            await raise_after_a_turn(exc)
    state = session.dest_state(dest)
    limit = state.slots.limit
    width = min(limit if window is None else min(window, limit), len(commands))
    if not session.on_asyncio or transport.fast_send is None or len(commands) == 1:
        if on_frame is not None:
            on_response = _frame_of(on_frame)
        responses = await _concurrent(
            session, commands, dest, timeout, idempotent, retries, width, on_response
        )
        return [] if on_frame is not None else responses
    await state.slots.acquire(timeout, f"{dest}")
    batch = Batch(
        session, commands, state, timeout, retries, width, on_response, idempotent, on_frame
    )
    batch.held = 1
    try:
        batch.start()
        await batch.fut
    finally:
        batch.cleanup()
    error = batch.error
    if error is not None:
        if isinstance(error, ConnectionLost):
            await raise_after_a_turn(error)
        raise error
    if on_frame is not None:
        return []
    results: list[Response] = batch.results  # type: ignore[assignment]  # all filled
    return results


def _options(
    session: Batching,
    commands: Sequence[Command],
    timeout: float | None,
    idempotent: bool,
    retries: int | None,
    window: int | None,
) -> tuple[float, int]:
    """A batch's ``timeout`` and ``retries`` (the session's where not given), its commands
    and ``window`` checked: :class:`CommandError` for what is out of range."""
    if timeout is None:
        timeout = session.timeout
    elif timeout <= 0:
        raise CommandError(f"timeout {shown(timeout)} must be positive")
    if retries is None:
        retries = session.retries if idempotent else 0
    elif retries < 0:
        raise CommandError(f"retries {retries} must not be negative")
    check_commands(commands)
    if window is not None and window < 1:
        raise CommandError(f"window {window} must be at least 1")
    return timeout, retries


def _frame_of(on_frame: OnFrame) -> OnResponse:
    """``on_frame`` as an ``on_response`` (the portable path makes its responses)."""

    def on_response(index: int, response: Response) -> None:
        on_frame(index, response.frame)

    return on_response


async def _concurrent(
    session: Batching,
    commands: Sequence[Command],
    dest: FinsAddress,
    timeout: float,
    idempotent: bool,
    retries: int,
    width: int,
    on_response: OnResponse | None,
) -> list[Response]:
    """The portable path: ``width`` loops of :meth:`Session.request`; the first error wins.

    The commands are one call: :meth:`Session.request_many` asked the circuit breaker for it
    (it may be the probe) and tells it how the call ended, so the commands do neither (a
    probe's own commands turned away by its probe kept the breaker from ever closing)."""
    results: list[Response | None] = [None] * len(commands)

    async def one(i: int) -> Response:
        mrc, src, params = commands[i]
        response = results[i] = await session.request(
            mrc, src, params, dest=dest, timeout=timeout, idempotent=idempotent,
            retries=retries, _in_call=True,
        )  # fmt: skip
        return response

    if width == 1:
        for i in range(len(commands)):
            response = await one(i)
            if on_response is not None:
                on_response(i, response)
        return results  # type: ignore[return-value]
    errors: list[Exception] = []
    cursor = iter(range(len(commands)))

    async def worker(scope: anyio.CancelScope) -> None:
        try:
            for i in cursor:
                response = await one(i)
                if on_response is not None and not errors:  # none after the first error
                    on_response(i, response)
        except Exception as exc:
            if not errors:
                errors.append(exc)
            scope.cancel()

    async with anyio.create_task_group() as tg:
        for _ in range(width):
            tg.start_soon(worker, tg.cancel_scope)
    if errors:
        raise errors[0]
    return results  # type: ignore[return-value]
