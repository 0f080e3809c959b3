"""The session: SIDs, the in-flight table, deadlines, retries and response matching.

Hot path (one request): take a slot of the destination, pick a SID, build the frame from a
pre-built header prefix, register the request in one dict keyed by the 32-bit
``SNA SA1 SA2 SID`` the reply will carry, push its deadline on one heap, send, await one
future. The transport pushes each reply to :meth:`Session.frame_received`, which finds the
request with a single dict lookup and resolves its future. No task and no timer per request:
one watcher task sleeps until the earliest deadline of the heap.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Sequence
from time import monotonic
from types import TracebackType
from typing import Any

import anyio
from anyio.abc import TaskGroup

from ..protocol.endcodes import EndCode
from ..protocol.errors import (
    CommandError,
    ConnectionLost,
    FinsError,
    FinsTimeout,
)
from ..protocol.header import DEFAULT_GCT, MAX_PARAMETER_SIZE, FinsAddress
from ..transport.base import Transport, is_asyncio
from .background import Background
from .batch import (
    _BUSY_CODES,
    _ERROR_BITS,
    _NORMAL,
    _SID_WAIT,
    _pack_head,
    check_command,
    end_code_error,
    raise_after_a_turn,
    request_many,
)
from .deadlines import Deadlines
from .matching import count_unmatched, match_relay_error, match_wildcard
from .response import RING_MASK, Response, SessionStats, new_response
from .slots import (
    AsyncioPending,
    DestState,
    EventPending,
    Pending,
    SlotQueue,
    SlotTimeout,
    no_free_sid_message,
)

#: Requests completed in a row without an event-loop pass before one is made to wait.
_POLL_STREAK = 32
#: At most this many requests skip the read-after-send after it found nothing.
_POLL_MAX_BACKOFF = 64


class _Attempt:
    """One connection attempt, run in the background and shared by every caller that needs
    the link while it runs; each waits for it at most its own timeout."""

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


class Session:
    """Multiplexes FINS requests over one transport.

    Use as ``async with Session(transport, source=..., dest=...) as s: await s.request(...)``.
    ``timeout`` is per attempt (waiting for a connection being made, for a free slot, for a
    free SID and for the reply are each bounded by it). A SID given up on stays quarantined
    until its late reply comes, or for ``max(quarantine_factor x timeout, min_quarantine)``
    seconds. Reads (``idempotent=True``) are retried ``retries`` times after a timeout, each
    time with a fresh SID; other requests only if the caller passes ``retries``. End codes
    2604/2605 (busy) are retried ``busy_retries`` times with a growing pause, as the command
    was not executed.
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
        busy_retries: int = 3,
        busy_backoff: float = 0.01,
        quarantine_factor: float = 2.0,
        min_quarantine: float = 15.0,
        reconnect_backoff: tuple[float, float] = (0.05, 5.0),
    ) -> None:
        if not 0 <= gct <= 0xFF:
            raise CommandError(f"GCT {gct} out of range 0..255")
        if not 1 <= max_in_flight <= 255:
            raise CommandError(f"max_in_flight {max_in_flight} out of range 1..255")
        if timeout <= 0:
            raise CommandError(f"timeout {timeout} must be positive")
        for name, count in (("retries", retries), ("busy_retries", busy_retries)):
            if count < 0:
                raise CommandError(f"{name} {count} must not be negative")
        if busy_backoff < 0:
            raise CommandError(f"busy_backoff {busy_backoff} must not be negative")
        if quarantine_factor <= 0:
            raise CommandError(f"quarantine_factor {quarantine_factor} must be positive")
        if not 0 <= min_quarantine < math.inf:
            raise CommandError(f"min_quarantine {min_quarantine} must be 0 or more seconds")
        low, high = reconnect_backoff
        if not 0 <= low <= high:
            raise CommandError(
                f"reconnect_backoff {reconnect_backoff} must be (min, max), 0 <= min <= max"
            )
        self.transport = transport
        self.source = source
        self.dest = dest
        self.gct = gct
        self.timeout = timeout
        self.retries = retries
        self.busy_retries = busy_retries
        self.busy_backoff = busy_backoff
        self.quarantine_factor = quarantine_factor
        self.min_quarantine = min_quarantine
        self.reconnect_backoff = reconnect_backoff
        limit = transport.max_in_flight
        self.max_in_flight = min(max_in_flight, limit) if limit else max_in_flight
        #: One request on the line at a time across all destinations (serial links).
        self._shared_slots = limit == 1
        self._pending: dict[int, Pending] = {}
        self._quarantine: dict[int, float] = {}
        #: Requests go to more than one destination: a SID is then kept unique across them,
        #: as a relay error (from the relay point, not the destination) is matched by SID.
        self._routed = False
        self._recent: dict[int, None] = {}
        self._dests: dict[FinsAddress, DestState] = {}
        self._slots: dict[Any, SlotQueue] = {}
        self._last_dest: FinsAddress | None = None
        self._last_state: Any = None
        self._deadlines = Deadlines()
        self._fifo = self._deadlines.fifo  # the in-order part, appended to inline
        self._timer_at = math.inf
        self._timer_scope: anyio.CancelScope | None = None
        self._tg: TaskGroup | None = None
        self._background: Background | None = None
        self._asyncio = False
        self._loop: Any = None  # the running asyncio loop, if any
        self._closed = False
        #: The connection attempt in progress, if any (one at a time, shared by callers).
        self._connecting: _Attempt | None = None
        self._backoff = 0.0
        self._retry_at = 0.0  # no connection attempt before this (monotonic) time
        self._poll_skip = self._poll_backoff = self._poll_streak = 0
        self._turn_due = False  # the next polled request yields to the event loop instead
        self.stats = SessionStats(self._pending)
        #: Requests awaiting a reply (read by datagram transports to stop draining early).
        self.replies_awaited = self._pending

    # ----------------------------------------------------------------- lifecycle

    async def __aenter__(self) -> Session:
        self._asyncio = is_asyncio()
        if self._asyncio:
            self._loop = asyncio.get_running_loop()
        tg = anyio.create_task_group()
        await tg.__aenter__()
        self._tg = tg
        self._background = Background(tg)
        try:
            self._background.start_soon(self._deadline_watcher)
            await self._ensure_open()
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

    @property
    def closed(self) -> bool:
        return self._closed

    async def aclose(self) -> None:
        """Fail every request in flight or queued with :class:`ConnectionLost`; close."""
        if self._closed:
            return
        self._closed = True
        attempt, self._connecting = self._connecting, None
        if attempt is not None:  # its waiters fail now; cancel_all() ends the attempt itself
            attempt.finish(
                ConnectionLost(f"session to {self.transport.description} closed while connecting")
            )
        self._fail_all(ConnectionLost(f"session to {self.transport.description} closed"))
        for q in self._slots.values():
            q.fail_waiters(ConnectionLost("session closed"))
        if self._background is not None:
            self._background.cancel_all()
        with anyio.CancelScope(shield=True):
            await self.transport.aclose()

    async def _ensure_open(self, timeout: float | None = None) -> None:
        """Open the transport if it is closed, waiting for it at most ``timeout`` seconds.

        One connection attempt at a time, run in the background (bounded by the transport's
        own connect timeout) and shared by every caller that comes while it runs. A caller
        whose ``timeout`` passes first gets :class:`FinsTimeout` and leaves the attempt
        running: a later call (or a retry) finds the link open or keeps waiting for the same
        attempt. ``timeout=None`` waits for the attempt's outcome (``async with session``).
        """
        if self.transport.is_open:
            return
        if self._closed:
            raise ConnectionLost(f"session to {self.transport.description} is closed")
        background = self._background
        if background is None:
            raise RuntimeError("Session is not running: use 'async with Session(...)'")
        attempt = self._connecting
        if attempt is None:
            wait = self._retry_at - monotonic()
            if wait > 0:  # fail fast: no call waits out the backoff beyond its own timeout
                raise ConnectionLost(
                    f"cannot connect to {self.transport.description}: the last attempt failed; "
                    f"the next one in {wait:.2f} s (reconnect backoff)"
                )
            attempt = self._connecting = _Attempt()
            background.start_soon(self._connect, attempt, background)
        if timeout is None:
            await attempt.done.wait()
        else:
            with anyio.move_on_after(timeout):
                await attempt.done.wait()
            if not attempt.done.is_set():
                raise FinsTimeout(
                    f"no connection to {self.transport.description} within {timeout} s: "
                    "a connection attempt is still in progress (a later call uses it once "
                    "it succeeds)"
                )
        attempt.check()

    async def _connect(self, attempt: _Attempt, background: Background) -> None:
        """Run one connection attempt (a background task: callers wait for it, bounded)."""
        error: BaseException | None = None
        try:
            await self.transport.open(self, background)
        except (OSError, FinsError) as exc:
            self.stats.connect_failures += 1
            low, high = self.reconnect_backoff
            self._backoff = min(high, max(low, self._backoff * 2))
            self._retry_at = monotonic() + self._backoff
            if isinstance(exc, FinsError):
                error = exc
            else:
                error = ConnectionLost(f"cannot connect to {self.transport.description}: {exc}")
                error.__cause__ = exc
        except Exception as exc:  # not a connection failure (a bug): its callers see it
            error = exc
        except BaseException:  # cancelled: the session is closing
            error = ConnectionLost(
                f"session to {self.transport.description} closed while connecting"
            )
            raise
        else:
            if self._closed:  # closed as the open completed: leave no link behind
                error = ConnectionLost(f"session to {self.transport.description} is closed")
                with anyio.CancelScope(shield=True):
                    await self.transport.aclose()
            else:
                self._backoff = 0.0
                self.stats.connects += 1
                node = self.transport.local_node
                if node is not None and node != self.source.node:
                    self.source = FinsAddress(self.source.network, node, self.source.unit)
                    for state in self._dests.values():
                        state.prefix = self._prefix(state.address)
        finally:
            if self._connecting is attempt:
                self._connecting = None
            attempt.finish(error)

    # ----------------------------------------------------------------- transport sink

    def frame_received(self, frame: bytes, _addr: object = None) -> None:
        """Called by the transport for each whole frame; never raises.

        (The unused second argument lets asyncio call this as ``datagram_received``.)
        """
        if len(frame) < 14:
            self.stats.malformed += 1
            return
        key = (frame[6] << 24) | (frame[7] << 16) | (frame[8] << 8) | frame[9]
        pending = self._pending
        p = pending.get(key)
        if p is None:
            p = match_wildcard(pending, key)
            if p is None and frame[12] & 0x80 and len(frame) >= 16:
                p = match_relay_error(pending, frame)
            if p is None:
                count_unmatched(self.stats, self._quarantine, self._recent, key)
                return
            key = p.key
        if frame[10] != p.mrc or frame[11] != p.src or frame[0] & 0x7E != 0x40:
            self.stats.mismatched += 1
            return
        if frame[12] & 0x80 and len(frame) < 16:
            self.stats.malformed += 1
            return
        del pending[key]
        self._recent[key] = None
        p.done = True
        fut = p.fut
        if fut is None:
            p.wake(frame)
        else:
            try:  # noqa: SIM105 (contextlib.suppress costs a context manager per reply)
                fut.set_result(frame)
            except asyncio.InvalidStateError:  # cancelled: the caller cleans up as it resumes
                pass
        stats = self.stats  # latency bookkeeping inlined: this runs once per reply
        latency = monotonic() - p.sent_at
        n = stats._lat_count
        stats._lat_count = n + 1
        stats._lat_sum += latency
        stats._lat_ring[n & RING_MASK] = latency
        fifo = self._fifo
        if fifo:
            if fifo[0].done:
                popleft = fifo.popleft
                popleft()
                while fifo and fifo[0].done:
                    popleft()
            elif len(fifo) > 64 + 4 * len(pending):
                # A slow request at the front keeps answered ones behind it: compact, rarely.
                self._deadlines.prune(len(pending))
        if self._deadlines.heap:
            self._deadlines.prune(len(pending))

    def frame_dropped(self, reason: str) -> None:
        self.stats.malformed += 1

    def connection_lost(self, exc: BaseException | None) -> None:
        if self._closed:
            return
        self.stats.disconnects += 1
        if isinstance(exc, FinsError):
            err: FinsError = exc
        else:
            err = ConnectionLost(f"connection to {self.transport.description} lost: {exc}")
            err.__cause__ = exc
        self._fail_all(err)

    def _fail_all(self, exc: BaseException) -> None:
        pending = list(self._pending.values())
        self._pending.clear()
        for p in pending:
            p.done = True
            p.fail(exc)
        self._deadlines.clear()

    # ----------------------------------------------------------------- deadlines

    async def _deadline_watcher(self) -> None:
        """The only timer: sleeps until the earliest deadline in the heap, expires what is due."""
        while True:
            self._expire(monotonic())
            at = self._deadlines.earliest()
            with anyio.CancelScope() as scope:
                self._timer_scope = scope
                self._timer_at = at
                if at != math.inf:
                    scope.deadline = anyio.current_time() + (at - monotonic())
                await anyio.sleep_forever()
            self._timer_scope = None

    def _arm(self, deadline: float) -> None:
        scope = self._timer_scope
        if deadline < self._timer_at and scope is not None:
            self._timer_at = deadline
            scope.deadline = anyio.current_time() + (deadline - monotonic())

    def quarantine_until(self, now: float, timeout: float) -> float:
        """When a SID given up on ``now`` (its request timed out or was cancelled) may be used
        again, unless its late reply comes first: ``max(quarantine_factor x timeout,
        min_quarantine)`` from now."""
        return now + max(self.quarantine_factor * timeout, self.min_quarantine)

    def _expire(self, now: float) -> None:
        for p in self._deadlines.due(now):
            self._pending.pop(p.key, None)
            p.done = True
            self._quarantine[p.key] = self.quarantine_until(now, p.deadline - p.sent_at)
            self.stats.timeouts += 1
            p.fail(FinsTimeout("request timed out"))

    # ----------------------------------------------------------------- requests

    def _dest_state(self, dest: FinsAddress) -> DestState:
        state = self._dests.get(dest)
        if state is None:
            if self._shared_slots:
                slots = self._slots.get(None)
                if slots is None:
                    slots = self._slots[None] = SlotQueue(self.max_in_flight)
            else:
                slots = self._slots[dest] = SlotQueue(self.max_in_flight)
            state = self._dests[dest] = DestState(dest, self._prefix(dest), slots)
            self._routed = len(self._dests) > 1
        self._last_dest, self._last_state = dest, state
        return state

    def _prefix(self, dest: FinsAddress) -> bytes:
        """ICF RSV GCT DNA DA1 DA2 SNA SA1 SA2: the header before the SID."""
        s = self.source
        return bytes(
            (0x80, 0, self.gct, dest.network, dest.node, dest.unit, s.network, s.node, s.unit)
        )

    def _sid_taken(self, key: int) -> bool:
        """Whether ``key``'s SID is in flight to another destination."""
        sid = key & 0xFF
        return any(k & 0xFF == sid for k in self._pending)

    def _allocate_sid(self, state: DestState) -> int | None:
        pending, quarantine = self._pending, self._quarantine
        base, sid = state.base, state.cursor
        now = 0.0
        for _ in range(256):
            key = base | sid
            sid = (sid + 1) & 0xFF
            if key in pending or (self._routed and self._sid_taken(key)):
                continue
            if quarantine:
                until = quarantine.get(key)
                if until is not None:
                    now = now or monotonic()
                    if until > now:
                        continue
                    del quarantine[key]
            state.cursor = sid
            return key
        return None

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
    ) -> Response:
        """Send one command and return its normal-completion response.

        Raises the :class:`EndCodeError` subclass for the end code (:class:`RelayError` for
        bit 15), :class:`FinsTimeout` when every attempt timed out (waiting for a connection
        still being made included), :class:`ConnectionLost` when the link failed or the
        session closed.
        """
        if dest is None:
            dest = self.dest
        if timeout is None:
            timeout = self.timeout
        elif timeout <= 0:
            raise CommandError(f"timeout {timeout} must be positive")
        if retries is None:
            retries = self.retries if idempotent else 0
        elif retries < 0:
            raise CommandError(f"retries {retries} must not be negative")
        if len(params) > MAX_PARAMETER_SIZE or not (0 <= mrc <= 0xFF and 0 <= src <= 0xFF):
            check_command(mrc, src, params)  # raises the error that says which
        attempt = busy = 0
        while True:
            # One attempt with a fresh SID, inlined (one coroutine per request, not two).
            try:
                transport = self.transport
                if transport.fast_send is None and not transport.is_open:
                    await self._ensure_open(timeout)
                state = self._last_state if dest is self._last_dest else self._dest_state(dest)
                slots = state.slots
                if slots.in_flight < slots.limit and not slots.waiters:
                    slots.in_flight += 1
                else:
                    await slots.acquire(timeout, f"{dest}")
                try:
                    pending = self._pending
                    key = state.base | state.cursor
                    if (
                        key in pending
                        or key in self._quarantine
                        or (self._routed and self._sid_taken(key))
                    ):
                        key = await self._wait_for_sid(state, timeout)
                    else:
                        state.cursor = (key + 1) & 0xFF
                    # Built before the request is registered: bad parameters (not bytes) raise
                    # here and leave nothing behind.
                    frame = _pack_head(state.prefix, key & 0xFF, mrc, src) + params
                    now = monotonic()
                    deadline = now + timeout
                    fut: asyncio.Future[bytes] | None = None
                    if self._asyncio:
                        fut = self._loop.create_future()
                        p: Pending = AsyncioPending(key, mrc, src, fut, now, deadline)
                    else:
                        p = EventPending(key, mrc, src)
                        p.sent_at = now
                        p.deadline = deadline
                    pending[key] = p
                    fifo = self._fifo
                    if not fifo or deadline >= fifo[-1].deadline:
                        fifo.append(p)
                    else:
                        self._deadlines.add(p)
                    if deadline < self._timer_at:
                        self._arm(deadline)
                    try:
                        fast_send = transport.fast_send
                        if fast_send is not None:
                            fast_send(frame)
                        else:
                            await transport.send(frame, timeout)
                        # Read-after-send (see _polled): for a request alone in flight.
                        if len(pending) == 1:
                            poll = transport.poll_now
                            if poll is not None:
                                if self._poll_skip:
                                    self._poll_skip -= 1
                                    self._poll_streak = 0
                                elif self._turn_due:  # fair turn (asyncio only): a bare yield
                                    self._turn_due = False
                                    await asyncio.sleep(0)
                                else:
                                    poll()
                                    self._polled(p.done)
                        else:  # concurrent callers: see _polled
                            self._poll_skip = _POLL_MAX_BACKOFF
                        frame = await (p.wait() if fut is None else fut)
                    except BaseException as exc:
                        if not p.done:  # cancelled or failed to send: the reply may still come
                            p.done = True
                            pending.pop(key, None)
                            self._quarantine[key] = self.quarantine_until(monotonic(), timeout)
                            if isinstance(exc, FinsTimeout):  # the send timed out (trio TCP)
                                self.stats.timeouts += 1
                            else:
                                self.stats.cancelled += 1
                        elif isinstance(exc, FinsTimeout):  # the deadline passed: say why
                            raise FinsTimeout(
                                self._timeout_message(dest, mrc, src, timeout)
                            ) from None
                        raise
                finally:
                    if slots.waiters:
                        slots.release()  # hands the slot to the first waiter
                    else:
                        slots.in_flight -= 1
            except FinsTimeout as exc:
                if attempt >= retries or isinstance(exc, SlotTimeout):
                    raise
                attempt += 1
                self.stats.retries += 1
                continue
            except ConnectionLost as exc:
                await raise_after_a_turn(exc)
            raw = (frame[12] << 8) | frame[13]
            if not raw & _ERROR_BITS:
                self.stats.completed += 1
                return new_response(_NORMAL if not raw else EndCode(raw), frame[14:], frame)
            end_code = EndCode(raw)
            if end_code.code in _BUSY_CODES and busy < self.busy_retries:
                self.stats.busy_retries += 1
                await anyio.sleep(self.busy_backoff * (2**busy))
                busy += 1
                continue
            self.stats.end_code_errors += 1
            raise end_code_error(frame, mrc, src)

    def _polled(self, answered: bool) -> None:
        """Score a read-after-send (``poll_now`` right after the send, request alone in flight).

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
        completed this way in a row, the next request yields to the event loop after its send
        instead, so other tasks, timers and cancellation run. The yield is a bare one, not a
        wait for that request's reply: under uvloop a reply already queued is read before the
        pass that runs anyio's cancellation retry, which then finds the task about to wake
        with a result and leaves it alone, turn after turn. (With many in flight the replies
        are read in one drain per loop pass instead, which is cheaper and keeps tasks fair.)
        Under trio the wait for a reply already there is a checkpoint all the same, so the
        request still yields; what the read saves is the reader task's wake-up.
        """
        if answered:
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
    ) -> list[Response]:
        """Send many commands ``(mrc, src, params)`` pipelined; their responses in order.

        Up to ``window`` (default and at most: the destination's in-flight cap) are on the
        wire at once. Under asyncio the replies are handled in the receive callback, which
        sends the next command, so the caller wakes once for the whole batch. Each command
        keeps the guarantees of :meth:`request` (timeouts per attempt, retries, busy end
        codes); the first error is raised after the rest are abandoned (SIDs quarantined).
        """
        return await request_many(
            self,
            requests,
            dest=dest,
            timeout=timeout,
            idempotent=idempotent,
            retries=retries,
            window=window,
        )

    async def _wait_for_sid(self, state: DestState, timeout: float) -> int:
        """A free SID; while all 256 are busy or quarantined, wait for the first release, up
        to ``timeout`` (then :class:`SlotTimeout`)."""
        key = self._allocate_sid(state)
        give_up = monotonic() + timeout
        while key is None:
            left = give_up - monotonic()
            if left <= 0:
                raise SlotTimeout(no_free_sid_message(state.address, timeout, self._quarantine))
            await anyio.sleep(min(_SID_WAIT, left))
            key = self._allocate_sid(state)
        return key

    def _timeout_message(self, dest: FinsAddress, mrc: int, src: int, timeout: float) -> str:
        s = self.source
        return (
            f"no response to command {mrc:02X}{src:02X} from {dest} within {timeout} s "
            f"via {self.transport.description}. Check the destination node (DA1={dest.node}) "
            f"and unit (DA2={dest.unit}) match the PLC, that our source node (SA1={s.node}) "
            f"is not used by another client and is allowed by the PLC's node settings, "
            f"the port, and that the PLC is reachable"
        )
