"""Per-request waiters and the per-destination in-flight limit (FIFO, cancellation-safe)."""

from __future__ import annotations

import asyncio
import contextlib
from collections import deque
from collections.abc import Generator
from types import TracebackType
from typing import Any, Protocol, cast

import anyio

from .._compiling import python_class
from ..protocol.errors import FinsTimeout
from ..protocol.header import FinsAddress
from ..transport.base import Transport
from .states import RequestState


class Registry(Protocol):
    """Where a request is registered (a :class:`~aiofins.session.sids.SidSpace`)."""

    def abandon(self, p: Pending, until: float) -> None: ...


class Space(Protocol):
    """An extra SID space as a request on it sees it (a
    :class:`~aiofins.session.spaces.ExtraSpace`): its SIDs and its transport."""

    @property
    def sids(self) -> Registry: ...

    @property
    def transport(self) -> Transport: ...


class Retransmission:
    """What the session needs to send a request again (only requests that may be retried
    carry one): the frame, how many more times, until when, and the current wait."""

    __slots__ = ("cap", "end", "frame", "left", "wait")

    def __init__(self, frame: bytes, left: int, end: float, cap: float | None, wait: float) -> None:
        #: The command frame, sent again as it is (same SID).
        self.frame = frame
        #: Retransmissions left.
        self.left = left
        #: The call's deadline (monotonic): no retransmission after it.
        self.end = end
        #: The per-attempt cap the caller asked for, if any.
        self.cap = cap
        #: The wait of the current attempt (doubled at each retransmission, RFC 6298 5.5).
        self.wait = wait


#: A request's retransmission plan as first registered (a tuple is cheaper to make than an
#: object, and most requests are answered at once): ``(frame, retries, end, cap, wait)``;
#: it becomes a :class:`Retransmission` at the first retransmission.
Plan = tuple[bytes, int, float, float | None, float]


class Pending:
    """One request on the wire: what its reply must carry and how to wake its caller.

    ``fut`` is the asyncio future the caller awaits (the session resolves it inline), or
    ``None`` for subclasses that wake their caller through :meth:`wake`. ``deadline`` is
    when the current attempt ends (a retransmission or, for the last, the call's end);
    ``rtt`` the destination whose round-trip estimate a reply updates (``None`` once sent
    again: Karn's rule, an ambiguous sample is not taken). ``end_code`` is set when the
    reply comes (the receive path reads it with the rest of the reply's head).
    """

    key: int
    mrc: int
    src: int
    done: bool
    #: When the current attempt ends.
    deadline: float
    #: The call's deadline: no transmission after it, no busy retry past it.
    end: float
    sent_at: float
    fut: asyncio.Future[bytes] | None
    attempts: int
    plan: Plan | Retransmission | None
    rtt: DestState | None
    abandoned: bool
    #: The extra SID space it went out on (``None``: the session's own transport).
    space: Space | None
    #: The in-flight slot it holds (``None``: none, or given back: see :meth:`free_slot`).
    slots: SlotQueue | None
    #: The reply frame, for a caller that may take it without a wait: a request answered
    #: before its caller waited (see :class:`AsyncioPending`) or by a driver that read it
    #: (:class:`HeldPending`); ``None`` otherwise (then ``await (p.fut or p.wait())``).
    reply: bytes | None
    end_code: int
    #: The frame as first sent (what it asked; ``b""`` before it is sent): the duplicate
    #: rule compares it with what a copy's request asked, and may send it again.
    frame: bytes

    __slots__ = (
        "abandoned",
        "attempts",
        "deadline",
        "done",
        "end",
        "end_code",
        "frame",
        "fut",
        "key",
        "mrc",
        "plan",
        "reply",
        "rtt",
        "sent_at",
        "slots",
        "space",
        "src",
    )

    def blank(self, key: int, mrc: int, src: int) -> None:
        """Set every field, for command ``mrc src`` under ``key``, not yet sent (records made
        outside :meth:`Session.start <aiofins.session.Session.start>`, which sets them all).
        ``Pending`` has no ``__init__``: a record made bare, ``AsyncioPending()``, costs no
        Python call (see docs/packaging.md)."""
        self.key = key
        self.mrc = mrc
        self.src = src
        self.done = False
        self.deadline = 0.0
        self.end = 0.0
        self.sent_at = 0.0
        self.fut = None
        self.attempts = 1
        self.plan = None
        self.frame = b""
        self.reply = None
        self.rtt = None
        self.abandoned = False
        self.space = None
        self.slots = None

    def free_slot(self) -> None:
        """Give back the in-flight slot this request holds, if any: its reply came, it was
        given up on, or its last transmission is presumed lost (past its retransmission
        timeout, a datagram occupies none of the PLC's capacity for commands)."""
        slots = self.slots
        if slots is not None:
            self.slots = None
            slots.release()

    @property
    def state(self) -> RequestState:
        """Where this request stands (in flight, or how it ended)."""
        if not self.done:
            return RequestState.SENT if self.attempts == 1 else RequestState.RETRANSMITTED
        return RequestState.ABANDONED if self.abandoned else RequestState.ANSWERED

    def unawaited(self) -> None:
        """Its caller gives up on it without awaiting it (its send failed): an error the
        link failed it with meanwhile is taken, not reported by asyncio as a future's
        exception never retrieved."""
        fut = self.fut
        if fut is not None and fut.done() and not fut.cancelled():
            fut.exception()

    def wake(self, frame: bytes) -> None:
        raise NotImplementedError

    def fail(self, exc: BaseException) -> None:
        raise NotImplementedError

    async def wait(self) -> bytes:
        raise NotImplementedError

    def __await__(self) -> Generator[Any, None, bytes]:
        """``frame = await p``: the reply frame (or the request's error raised)."""
        return self.wait().__await__()


class AsyncioPending(Pending):
    """Waits on a bare asyncio future, the cheapest wake-up asyncio has, made only when its
    caller has to wait: a request answered by the read right after its send (see
    :meth:`Session.begin <aiofins.session.Session.begin>`) keeps its reply in
    :attr:`reply` and never has one.

    Made bare, ``AsyncioPending()`` (no ``__init__`` in its classes: no Python call):
    :meth:`Session.start` sets every field, the caller :attr:`fut` (or not) and
    :attr:`slots`."""

    __slots__ = ()

    def wake(self, frame: bytes) -> None:
        fut = self.fut
        if fut is None:  # answered before its caller waits
            self.reply = frame
        elif not fut.done():
            fut.set_result(frame)

    def fail(self, exc: BaseException) -> None:
        fut = self.fut
        if fut is None:  # failed before its caller waits (its send, or the link's failure)
            self.fut = fut = asyncio.get_running_loop().create_future()
        if not fut.done():
            fut.set_exception(exc)

    async def wait(self) -> bytes:
        reply = self.reply
        if reply is not None:
            return reply
        return await cast("asyncio.Future[bytes]", self.fut)

    def __await__(self) -> Generator[Any, None, bytes]:
        fut = self.fut  # the future itself, when there is one: no coroutine of ours
        return self.wait().__await__() if fut is None else fut.__await__()


class EventPending(Pending):
    """Waits on an anyio event (trio and other backends)."""

    __slots__ = ("event", "result", "traceback")

    def __init__(self, key: int, mrc: int, src: int) -> None:
        self.blank(key, mrc, src)
        self.event = anyio.Event()
        self.result: bytes | BaseException | None = None
        self.traceback: TracebackType | None = None

    def wake(self, frame: bytes) -> None:
        if self.result is None:
            self.result = frame
            self.event.set()

    def fail(self, exc: BaseException) -> None:
        if self.result is None:
            self.result = exc
            self.traceback = exc.__traceback__
            self.event.set()

    async def wait(self) -> bytes:
        await self.event.wait()
        result = self.result
        if isinstance(result, BaseException):
            # One error fails every request in flight: raised as is, its traceback would
            # grow by each earlier request's frames (so, as an asyncio future, with the
            # traceback it came with).
            raise result.with_traceback(self.traceback)
        assert result is not None
        return result


class HeldPending(Pending):
    """Keeps its reply (or its failure) in :attr:`result` for a caller that reads it there
    itself: a driver without an event loop, which waits on its socket (see
    :mod:`aiofins.sync`), not on a future or an event. Made bare, ``HeldPending()``:
    :meth:`Session.start` sets the other fields."""

    __slots__ = ("result",)

    def __init__(self) -> None:
        self.fut = None
        self.slots = None
        #: The reply frame, or the error the request ended with; ``None`` until then.
        self.result: bytes | BaseException | None = None

    def wake(self, frame: bytes) -> None:
        if self.result is None:
            self.result = self.reply = frame

    def fail(self, exc: BaseException) -> None:
        if self.result is None:
            self.result = exc

    async def wait(self) -> bytes:
        result = self.result
        if isinstance(result, BaseException):
            raise result
        if result is None:
            raise RuntimeError("a held request is read once it has ended")
        return result


@python_class
class SlotTimeout(FinsTimeout):
    """No request slot (or no free SID) became free in time: the destination's queue did not
    drain, or all 256 of its SIDs are in flight, quarantined or lingering.

    Not retried: a retry would only queue again behind the same requests.
    """


class _Waiter:
    __slots__ = ("error", "event", "granted", "traceback")

    def __init__(self) -> None:
        self.event = anyio.Event()
        self.granted = False
        self.error: BaseException | None = None
        self.traceback: TracebackType | None = None


class SlotQueue:
    """At most ``limit`` requests in flight; the rest wait first come, first served."""

    __slots__ = ("in_flight", "limit", "waiters")

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.in_flight = 0
        self.waiters: deque[_Waiter] = deque()

    def try_acquire(self) -> bool:
        if self.in_flight < self.limit and not self.waiters:
            self.in_flight += 1
            return True
        return False

    async def acquire(self, timeout: float, what: str) -> None:
        """Wait for a slot; :class:`FinsTimeout` after ``timeout`` seconds."""
        if self.try_acquire():
            return
        waiter = _Waiter()
        self.waiters.append(waiter)
        try:
            with anyio.move_on_after(timeout):
                await waiter.event.wait()
        except BaseException:
            self._abandon(waiter)
            raise
        if waiter.error is not None:
            raise waiter.error.with_traceback(waiter.traceback)  # shared: see EventPending
        if not waiter.granted:
            self._abandon(waiter)
            raise SlotTimeout(
                f"no free request slot for {what} within {timeout} s: "
                f"{self.in_flight} requests in flight did not complete"
            )

    def _abandon(self, waiter: _Waiter) -> None:
        if waiter.granted:
            self.release()  # the slot was handed over as we gave up: pass it on
        else:
            with contextlib.suppress(ValueError):
                self.waiters.remove(waiter)

    def release(self) -> None:
        if self.waiters:
            waiter = self.waiters.popleft()
            waiter.granted = True  # the slot moves to the waiter: in_flight unchanged
            waiter.event.set()
        else:
            self.in_flight -= 1

    def fail_waiters(self, exc: BaseException) -> None:
        while self.waiters:
            waiter = self.waiters.popleft()
            waiter.error = exc
            waiter.traceback = exc.__traceback__
            waiter.event.set()


class DestState:
    """Per-destination state: header prefix, SID cursor, in-flight slots and the round-trip
    estimate (RFC 6298: ``srtt``, ``rttvar``, and ``rto`` clamped to the session's bounds;
    ``srtt == 0.0`` until the first sample)."""

    __slots__ = (
        "address",
        "base",
        "cursor",
        "keys",
        "prefix",
        "rto",
        "rttvar",
        "sid_lock",
        "slots",
        "srtt",
    )

    def __init__(self, address: FinsAddress, prefix: bytes, slots: SlotQueue) -> None:
        self.address = address
        self.base = (address.network << 24) | (address.node << 16) | (address.unit << 8)
        #: The 256 keys of the destination's SIDs (``base + sid``), made once: the request
        #: path takes its key from here, so the in-flight table and the tables of replies
        #: meet the same int object for a SID and compare it by identity, not by value.
        self.keys = tuple(range(self.base, self.base + 256))
        self.cursor = 0
        self.prefix = prefix
        self.slots = slots
        self.srtt = 0.0
        self.rttvar = 0.0
        self.rto = 0.0
        #: Held by the one request looking for a free SID while all 256 are taken.
        self.sid_lock: anyio.Lock | None = None

    def sample(self, latency: float, bounds: tuple[float, float] | None) -> None:
        """Update the estimate with one round trip (RFC 6298 2.2, 2.3; Karn: only replies
        to a single transmission are timed) and, with ``bounds`` (low, high), the
        retransmission timeout within them (without: over a reliable stream ``rto`` stays
        unset, see :meth:`Session.start`)."""
        srtt = self.srtt
        if srtt:
            err = latency - srtt
            self.srtt = srtt = srtt + 0.125 * err
            var = self.rttvar = self.rttvar + 0.25 * ((err if err > 0 else -err) - self.rttvar)
        else:
            self.srtt = srtt = latency
            var = self.rttvar = 0.5 * latency
        if bounds is not None:
            rto = srtt + 4 * var
            low, high = bounds
            self.rto = low if rto < low else high if rto > high else rto
