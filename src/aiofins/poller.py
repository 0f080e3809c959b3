"""A polling engine: scan groups over one or many PLCs, delivered as timestamped snapshots.

Each scan group reads its tag list (compiled once into the fewest frames, see
:mod:`aiofins.tags`) from one endpoint every ``interval`` seconds, through a
:class:`~aiofins.pool.Pool`, on its own, so a slow or dead PLC never delays the others. One
timer keeps every group's next scan time and starts the groups that are due: under asyncio
it sends a scan's frames itself and the scan ends in the session's receive callback
(:func:`~aiofins.session.callback.start_requests`), no task woken; otherwise, and whenever
that cannot start at once, the group's own task scans. Scans are
deadline-driven: a scan that overruns makes the group skip the scan times it missed (counted in
:attr:`ScanGroup.missed`), never queue them up. Snapshots go through a bounded buffer; when the
consumer is slower than the scans, groups wait for room (backpressure) and the scans they miss
meanwhile are counted the same way.

Every tag of a snapshot carries a quality: ``GOOD`` (read in this scan), ``STALE`` (this scan
failed, or the tag's words were no value of its type, such as invalid BCD; the value is the
last good one, with its timestamp) or ``ERROR`` (the same with no good value yet, or the tag's
address is refused).

::

    async with aiofins.Pool() as pool, Poller(pool) as poller:
        poller.add_group("line1", "udp://10.0.0.5", {"temp": "D100:float32"}, interval=0.5)
        async for snap in poller:
            print(snap.group, snap["temp"].value, snap["temp"].quality)
"""

from __future__ import annotations

import asyncio
import heapq
import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Mapping, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field
from enum import Enum
from functools import partial
from types import TracebackType
from typing import TYPE_CHECKING

import anyio
from anyio.abc import TaskGroup

from ._channel import Channel, Wake
from ._scanstep import FrameScan, OneFrame
from .client import add_addressing_hint
from .endpoint import parse_endpoint
from .hooks import EventHooks, ScanDone
from .pool import backend_sleep, event_loop_clock
from .protocol.endcodes import EndCode
from .protocol.errors import CommandError, EndCodeError, FinsError
from .protocol.frames import END_CODE, MIN_REPLY_SIZE
from .protocol.values import Value
from .session.callback import CallbackBatch, CallbackPending, start_requests
from .session.response import new_response
from .tags import ReadPlan, TagNames, parse_tag
from .transport.base import is_asyncio

if TYPE_CHECKING:
    from .client import Client
    from .pool import Pool, _Lease
    from .session import Response

logger = logging.getLogger("aiofins.poller")


#: Seconds between two warnings about one group's missed scans (the count says how many).
MISSED_WARNING_INTERVAL = 60.0


class Quality(Enum):
    """How far a :class:`TagReading`'s value can be trusted."""

    #: Read in this scan.
    GOOD = "good"
    #: This scan failed (or the tag's words were no value of its type): the value is the
    #: last good one, kept; ``error`` says why.
    STALE = "stale"
    #: No good value yet: every scan of the tag so far failed; ``value`` is ``None``.
    ERROR = "error"


@dataclass(frozen=True)
class TagReading:
    """One tag in a snapshot: value, quality, when the value was read, why it is not good."""

    value: Value | None
    quality: Quality
    timestamp: float | None
    error: str | None = None


@dataclass(frozen=True)
class Snapshot:
    """The result of one scan of one group."""

    group: str
    endpoint: str
    scan: int
    timestamp: float
    duration: float
    readings: Mapping[str, TagReading]
    changed: frozenset[str]
    error: str | None = None

    def __getitem__(self, tag: str) -> TagReading:
        return self.readings[tag]

    @property
    def values(self) -> dict[str, Value | None]:
        readings = self.readings
        if isinstance(readings, GoodReadings):
            return readings.values_by_name()  # type: ignore[return-value]
        return {name: r.value for name, r in readings.items()}


class PollerState(Enum):
    """Where a :class:`Poller` is in its life (:attr:`Poller.state`)."""

    #: Made, not entered: groups may be added; they start when it is entered.
    NEW = "new"
    #: Entered (``async with``): its timer runs and its groups scan.
    RUNNING = "running"
    #: Left: its groups stopped, its iteration ended. A poller runs once.
    CLOSED = "closed"


#: The transitions :meth:`Poller._become` allows.
_POLLER_NEXT: dict[PollerState, frozenset[PollerState]] = {
    PollerState.NEW: frozenset({PollerState.RUNNING}),
    PollerState.RUNNING: frozenset({PollerState.CLOSED}),
    PollerState.CLOSED: frozenset(),
}


class TimerState(Enum):
    """Where the poller's one timer is (see :meth:`Poller._timer`)."""

    #: No scan time on the schedule: the next group added wakes it.
    IDLE = "idle"
    #: Waiting for the earliest scan time (``Poller._timer_at``): an earlier one moves it.
    ARMED = "armed"
    #: Starting the groups that are due, and planning their next scan times: nothing need
    #: wake it.
    STARTING = "starting"


class ScanState(Enum):
    """Where a scan group is in its cycle (:attr:`ScanGroup.state`)."""

    #: Added, not yet started (the poller is not running).
    STOPPED = "stopped"
    #: Waiting for its next scan time.
    IDLE = "idle"
    #: Its scan time came: the poller's timer woke its task, whose scan starts. (A scan the
    #: timer sends itself goes from IDLE to SCANNING.)
    DUE = "due"
    #: Reading its tags.
    SCANNING = "scanning"
    #: Waiting for room in the poller's buffer to deliver its snapshot (backpressure).
    DELIVERING = "delivering"

    #: Members are singletons: hash them by identity in C (Enum's own hash is a Python
    #: call, paid three times per scan by the transition table).
    __hash__ = object.__hash__


#: The transitions :meth:`ScanGroup._enter` allows.
_NEXT_STATES: dict[ScanState, frozenset[ScanState]] = {
    ScanState.STOPPED: frozenset({ScanState.IDLE}),
    ScanState.IDLE: frozenset({ScanState.DUE, ScanState.SCANNING, ScanState.STOPPED}),
    ScanState.DUE: frozenset({ScanState.SCANNING, ScanState.STOPPED}),
    ScanState.SCANNING: frozenset({ScanState.DELIVERING, ScanState.IDLE, ScanState.STOPPED}),
    ScanState.DELIVERING: frozenset({ScanState.IDLE, ScanState.STOPPED}),
}


@dataclass
class ScanGroup:
    """A tag list read from one endpoint every ``interval`` seconds, with its counters.

    ``missed`` counts the scan times that passed while the group was still busy with an
    earlier scan (or the event loop was too late to start it): each is skipped, never queued.
    """

    name: str
    url: str
    tags: Mapping[str, str]
    interval: float
    timeout: float | None = None
    scans: int = 0
    errors: int = 0
    missed: int = 0
    last_duration: float = 0.0
    plan: ReadPlan | None = None
    state: ScanState = ScanState.STOPPED
    _last: Mapping[str, TagReading] = field(default_factory=dict)
    #: The values of the last scan, in the plan's tag order, when every tag was good in it
    #: (else None).
    _last_good: tuple[Value, ...] | None = None
    _wake: Wake = field(default_factory=Wake, repr=False)
    #: The error of the last failed scan while scans fail (logged once per outage).
    _failing: str | None = None
    #: Missed scans not yet warned about, and when the last warning was logged.
    _missed_unlogged: int = 0
    _missed_logged_at: float = -math.inf
    #: Whether the scan in flight said (INFO) that it waits for the PLC while scan times pass.
    _waiting_said: bool = False
    #: ``missed`` when the last ScanDone was emitted (the next one says how many since).
    _missed_reported: int = 0
    #: The pool lease the group's scans borrow the endpoint's client with (kept between scans).
    _lease: _Lease | None = field(default=None, repr=False)
    #: The scan of several frames in flight on the callback path (see
    #: :meth:`Poller._scan_soon`), if any: (its batch, the lease, the client lent, when it
    #: started: loop clock, wall clock).
    _scan: tuple[CallbackBatch, _Lease, Client, float, float] | None = field(
        default=None, repr=False
    )
    #: What ends such a scan (the poller's :meth:`~Poller._scanned_soon` for this group).
    _done: Callable[[list[Response] | None, BaseException | None], None] | None = field(
        default=None, repr=False
    )
    #: The scan step of a plan of one frame on the callback path, kept between scans
    #: (made at its first such scan; dropped when its lease or client changes).
    _step: FrameScan | None = field(default=None, repr=False)
    #: The plan's one frame, made once: (its command, the decoder of its reply frame, or
    #: None); ``()`` for a plan of several frames (sent as a batch); ``None``: not made yet.
    _one: OneFrame | tuple[()] | None = field(default=None, repr=False)
    #: A snapshot of the callback path for the group's task to deliver (backpressure).
    _undelivered: Snapshot | None = field(default=None, repr=False)

    def _in_flight(self) -> CallbackBatch | CallbackPending | None:
        """The request(s) of its scan in flight on the callback path, if any."""
        if self._scan is not None:
            return self._scan[0]
        step = self._step
        return None if step is None else step.request

    def _enter(self, state: ScanState) -> None:
        """The one place a group changes state."""
        if state not in _NEXT_STATES[self.state]:
            raise RuntimeError(f"scan group {self.name!r}: {self.state.name} -> {state.name}")
        self.state = state


class Poller:
    """Runs scan groups; iterate it for snapshots (``async for snap in poller``).

    ``changes_only`` delivers only the tags whose value or quality changed (and skips
    snapshots with no change); ``buffer`` is how many snapshots may wait for the consumer.
    ``hooks`` receive a :class:`~aiofins.ScanDone` per scan (default: the pool's ``hooks``,
    which also get the requests' events).
    """

    def __init__(
        self,
        pool: Pool,
        *,
        buffer: int = 64,
        changes_only: bool = False,
        hooks: EventHooks | None = None,
    ) -> None:
        self.pool = pool
        if hooks is None:
            hooks = pool.connect_options.get("hooks")
        self.hooks = hooks
        self._hooks = None if hooks is None else hooks.or_none()
        self.changes_only = changes_only
        self.groups: dict[str, ScanGroup] = {}
        self.state = PollerState.NEW
        self._channel: Channel[Snapshot] = Channel(buffer)
        self._tg: TaskGroup | None = None
        self._now = anyio.current_time
        self._sleep: Callable[[float], Awaitable[None]] = anyio.sleep
        #: (next scan time, order added, group): the one timer's schedule.
        self._schedule: list[tuple[float, int, ScanGroup]] = []
        self._added = 0
        self._timer_state = TimerState.IDLE
        self._timer_at = math.inf  # when it fires next (-inf: starting; inf: idle)
        self._timer_scope: anyio.CancelScope | None = None
        self._timer_wake = Wake()
        #: Under asyncio: the running loop and the timer's next run (see _tick).
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tick_handle: asyncio.TimerHandle | None = None

    def add_group(
        self,
        name: str,
        url: str,
        tags: Mapping[str, str],
        *,
        interval: float = 1.0,
        timeout: float | None = None,
    ) -> ScanGroup:
        """Add a scan group; starts at once if the poller is running.

        The URL and every tag are checked here (a bad one raises :class:`CommandError` or
        :class:`AddressError` now, not as an error in every scan).
        """
        if name in self.groups:
            raise CommandError(f"scan group {name!r} exists already")
        if not interval > 0 or not math.isfinite(interval):
            raise CommandError(f"interval must be a positive number of seconds, got {interval}")
        if timeout is not None and not timeout > 0:
            raise CommandError(f"timeout must be a positive number of seconds, got {timeout}")
        if not tags:
            raise CommandError(f"scan group {name!r} has no tags")
        parse_endpoint(url)
        for tag_name, spec in tags.items():
            parse_tag(tag_name, spec)
        group = ScanGroup(name, url, dict(tags), interval, timeout)
        self.groups[name] = group
        if self._tg is not None:
            self._start(group)
        return group

    def _start(self, group: ScanGroup, now: float | None = None) -> None:
        """Start ``group``'s task and schedule its first scan now."""
        assert self._tg is not None
        group._wake.bind()
        group._done = partial(self._scanned_soon, group)
        group._enter(ScanState.IDLE)
        self._tg.start_soon(self._run_group, group)
        self._plan_scan(self._now() if now is None else now, group)

    def _plan_scan(self, when: float, group: ScanGroup) -> None:
        self._added += 1
        heapq.heappush(self._schedule, (when, self._added, group))
        if when < self._timer_at:  # earlier than the timer fires (idle: never): move it
            if self._loop is not None:  # (asyncio: an event-loop timer)
                self._arm(when)
            elif self._timer_scope is not None:  # (the timer task sleeps in a scope)
                self._timer_scope.cancel()
            else:
                self._timer_wake.set()

    def _become(self, state: PollerState) -> None:
        """The one place the poller changes state."""
        if state not in _POLLER_NEXT[self.state]:
            raise RuntimeError(
                f"the poller is {self.state.name.lower()}"
                + (
                    ": a poller runs once, make a new one"
                    if self.state is not PollerState.NEW
                    else ""
                )
            )
        self.state = state

    async def __aenter__(self) -> Poller:
        self._become(PollerState.RUNNING)
        self._now = event_loop_clock()
        self._sleep = backend_sleep()
        self._channel.bind()
        self._timer_wake.bind()
        self._tg = anyio.create_task_group()
        await self._tg.__aenter__()
        self._tg.start_soon(self._timer)
        now = self._now()  # the groups added before start share one time grid
        for group in self.groups.values():
            self._start(group, now)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        assert self._tg is not None
        self._tg.cancel_scope.cancel()
        try:
            return await self._tg.__aexit__(exc_type, exc, tb)
        finally:
            self._tg = None
            self._schedule.clear()
            self._timer_to(TimerState.IDLE)
            for group in self.groups.values():
                scan = group._scan
                if scan is not None:  # a scan on the callback path: given up
                    group._scan = None
                    scan[0].cancel()
                    scan[1].release()
                    if group._lease is None:
                        group._lease = scan[1]
                if group._step is not None:
                    group._step.give_up()
                group._undelivered = None
                if group.state is not ScanState.STOPPED:
                    group._enter(ScanState.STOPPED)
            self._channel.close()
            self._become(PollerState.CLOSED)

    def __aiter__(self) -> AsyncIterator[Snapshot]:
        return self._channel

    async def _timer(self) -> None:
        """The one timer of all groups: sleeps until the earliest scan time, starts each group
        that is due, and puts its next scan time on the schedule (a group still busy then
        misses that scan, counted). Under asyncio it is an event-loop timer instead (see
        :meth:`_tick`), which this task arms and disarms."""
        if is_asyncio():
            self._loop = asyncio.get_running_loop()
            try:
                self._tick()
                await anyio.sleep_forever()
            finally:
                if self._tick_handle is not None:
                    self._tick_handle.cancel()
                    self._tick_handle = None
                self._loop = None
        clock, sleep, schedule = self._now, self._sleep, self._schedule
        wake = self._timer_wake
        while True:
            if not schedule:
                self._timer_to(TimerState.IDLE)
                await wake.wait()
                continue
            now = clock()
            when = schedule[0][0]
            if when > now + _TIMER_SLACK:
                self._timer_to(TimerState.ARMED, when)
                with anyio.CancelScope() as scope:
                    self._timer_scope = scope
                    await sleep(when - now)
                self._timer_scope = None
                continue
            self._timer_to(TimerState.STARTING)
            self._start_due(now + _TIMER_SLACK, None)

    def _tick(self) -> None:
        """The timer under asyncio: an event-loop timer that starts the due scans (each sent
        from here, see :meth:`_scan_soon`) and re-arms itself for the next scan time. No
        task wakes per scan time."""
        self._tick_handle = None
        schedule = self._schedule
        try:
            if schedule and schedule[0][0] <= self._now() + _TIMER_SLACK:
                self._timer_to(TimerState.STARTING)
                self._start_due(self._now() + _TIMER_SLACK, self._scan_soon)
        except Exception:  # a bug: logged, and the timer goes on
            logger.exception("the poller's timer failed")
        finally:
            if schedule:
                self._arm(schedule[0][0])
            else:
                self._timer_to(TimerState.IDLE)

    def _arm(self, when: float) -> None:
        """(asyncio) Run :meth:`_tick` at ``when`` instead of when it was due to run."""
        assert self._loop is not None
        if self._tick_handle is not None:
            self._tick_handle.cancel()
        self._timer_to(TimerState.ARMED, when)
        self._tick_handle = self._loop.call_at(when, self._tick)

    def _timer_to(self, state: TimerState, at: float = math.inf) -> None:
        """The one place the timer changes state (``at``: when an ARMED timer fires)."""
        self._timer_state = state
        if state is TimerState.ARMED:
            self._timer_at = at
        else:
            self._timer_at = math.inf if state is TimerState.IDLE else -math.inf

    def _start_due(self, now: float, scan_soon: Callable[[ScanGroup], bool] | None) -> None:
        """Start every group whose scan time is ``now`` or earlier (from ``scan_soon`` if it
        can, else on the group's task) and plan its next scan time."""
        schedule = self._schedule
        pop, push = heapq.heappop, heapq.heappush
        idle, due = ScanState.IDLE, ScanState.DUE
        while schedule and schedule[0][0] <= now:
            when, order, group = pop(schedule)
            interval = group.interval
            late = 0  # scan times already gone
            if now - when >= interval:
                late = math.floor((now - when) / interval)
                when += late * interval
            if group.state is idle:
                if scan_soon is None:
                    started = False
                elif (step := group._step) is not None:  # (a plan of one frame)
                    started = step.start()
                else:
                    started = scan_soon(group)
                if not started:
                    group._enter(due)
                    group._wake.set()  # the group's task scans
            else:
                late += 1
            if late:
                group.missed += late
                self._missed(group, late, now)
            push(schedule, (when + interval, order, group))

    def _missed(self, group: ScanGroup, skipped: int, now: float) -> None:
        """Count missed scans; warn at the first and then at most once a minute per group.

        Not while the scan in flight waits for the PLC: a dead PLC's first line would be
        "cannot keep up" before the timeout that is the cause. Said once per scan what it
        waits for instead; the scan's outcome decides (:meth:`_waited`)."""
        group._missed_unlogged += skipped
        if group.state is ScanState.SCANNING:
            if not group._waiting_said:
                group._waiting_said = True
                logger.info(
                    "scan group %s: its scan waits for %s to answer (timeout %s); scan times "
                    "pass meanwhile (interval %.3g s)",
                    group.name,
                    group.url,
                    "the endpoint's" if group.timeout is None else f"{group.timeout:g} s",
                    group.interval,
                    extra={"group": group.name, "endpoint": group.url},
                )
            return
        self._warn_missed(group, now)

    def _waited(self, group: ScanGroup, failed: bool) -> str:
        """A scan that let scan times pass ended: a failure is their cause (its warning says
        how many, returned here); a scan that succeeded too slowly warns "cannot keep up"."""
        group._waiting_said = False
        skipped = group._missed_unlogged
        if not skipped:
            return ""
        if failed:
            group._missed_unlogged = 0
            return f" ({skipped} scan time{'s' if skipped > 1 else ''} passed while it waited)"
        self._warn_missed(group, self._now())
        return ""

    def _warn_missed(self, group: ScanGroup, now: float) -> None:
        if now - group._missed_logged_at < MISSED_WARNING_INTERVAL:
            return
        logger.warning(
            "scan group %s missed %d scans (last scan took %.3f s, interval %.3g s): "
            "the PLC, the pool or the consumer cannot keep up",
            group.name,
            group._missed_unlogged,
            group.last_duration,
            group.interval,
            extra={"group": group.name, "endpoint": group.url},
        )
        group._missed_unlogged = 0
        group._missed_logged_at = now

    async def _run_group(self, group: ScanGroup) -> None:
        channel = self._channel
        wake = group._wake
        logger.info(
            "scan group %s started: %d tags from %s every %.3g s",
            group.name,
            len(group.tags),
            group.url,
            group.interval,
            extra={"group": group.name, "endpoint": group.url},
        )
        try:
            while True:
                await wake.wait()
                if group.state is ScanState.DELIVERING:  # a callback scan's, the buffer full
                    snapshot = group._undelivered
                    group._undelivered = None
                    assert snapshot is not None
                    await channel.send(snapshot)
                else:
                    group._enter(ScanState.SCANNING)
                    snapshot = await self.scan_once(group)
                    if snapshot is not None and not channel.send_nowait(snapshot):
                        group._enter(ScanState.DELIVERING)  # full: wait for the consumer
                        await channel.send(snapshot)
                group._enter(ScanState.IDLE)
                self._scan_done(group)
        finally:
            logger.info(
                "scan group %s stopped after %d scans (%d failed, %d missed)",
                group.name,
                group.scans,
                group.errors,
                group.missed,
                extra={"group": group.name, "endpoint": group.url},
            )

    def _scan_done(self, group: ScanGroup) -> None:
        """A scan ended (its snapshot delivered): the hooks' :class:`ScanDone`."""
        hooks = self._hooks
        if hooks is not None and hooks.scan_done:
            skipped = group.missed - group._missed_reported
            group._missed_reported = group.missed
            hooks.emit(
                hooks.scan_done,
                ScanDone(group.name, group.scans, group.last_duration, skipped, group._failing),
            )

    def _scan_soon(self, group: ScanGroup) -> bool:
        """Start ``group``'s due scan from the timer's own step (asyncio): its frames go out
        now and the scan ends in the session's receive callback (:meth:`_scanned_soon`),
        no task woken for it. A plan of one frame gets its scan step here, kept for the
        next scans (:class:`~aiofins._scanstep.FrameScan`). False (nothing started, the
        group's task scans instead) when it cannot start at once: the group's first scan
        (it compiles the plan), no session ready to lend, a plan the client must check
        first, or the session's own conditions (link open, breaker closed, a slot free: see
        :func:`~aiofins.session.callback.start_requests`)."""
        plan = group.plan
        lease = group._lease
        done = group._done
        if plan is None or lease is None or done is None:
            return False
        client = lease.borrow_ready()
        if client is None:
            lease.release()
            return False
        limits = client.limits
        if plan.cache.get("fits") is not limits:
            lease.release()
            return False
        one = group._one
        if one is None:
            one = group._one = _one_frame(plan)
        if one:
            lease.release()  # (the step borrows it for each scan)
            step = group._step = FrameScan(
                self, group, lease, client, limits, one, ScanState.SCANNING, ScanState.IDLE
            )
            return step.start()
        started = self._now()
        request: CallbackBatch | None
        try:
            request = start_requests(
                client.session, plan.scan_commands()[0], done, dest=client.dest,
                timeout=group.timeout,
            )  # fmt: skip
        except Exception:  # a bug, not the PLC: the group's task scans (and says what)
            logger.exception("scan group %s: the scan could not start", group.name)
            request = None
        if request is None:
            lease.release()
            return False
        group._lease = None  # in use (a scan_once beside this scan takes another)
        group._scan = (request, lease, client, started, time.time())
        group._enter(ScanState.SCANNING)
        group.scans += 1
        return True

    def _scanned_frame(
        self,
        group: ScanGroup,
        client: Client,
        started: float,
        stamp: float,
        frame: bytes | None,
        error: BaseException | None,
    ) -> None:
        """A scan of one frame (:class:`~aiofins._scanstep.FrameScan`) ended whose frame the
        plan's decoder did not take (a failure, a frame of another size, words no value of
        their type): decoded tag by tag, as :meth:`_scanned_soon` does."""
        if frame is None:
            self._end_scan(group, client, started, stamp, None, error)
            return
        raw = int.from_bytes(frame[END_CODE:MIN_REPLY_SIZE], "big")
        response = new_response(EndCode(raw), frame[MIN_REPLY_SIZE:], frame)
        self._end_scan(group, client, started, stamp, [response], None)

    def _scanned_soon(
        self, group: ScanGroup, responses: list[Response] | None, error: BaseException | None
    ) -> None:
        """A scan of :meth:`_scan_soon` ended (called by the session): its snapshot goes to
        the buffer, or, if the buffer is full, to the group's task to wait for room."""
        scan = group._scan
        if scan is None:  # (given up by the poller's exit)
            return
        group._scan = None
        _, lease, client, started, stamp = scan
        lease.release()
        if group._lease is None:
            group._lease = lease
        try:
            self._end_scan(group, client, started, stamp, responses, error)
        except Exception:  # a bug, not the PLC: logged, and the group scans on
            logger.exception("scan group %s: the scan could not end", group.name)
            group.errors += 1
            if group.state is ScanState.SCANNING:
                group._enter(ScanState.IDLE)

    def _end_scan(
        self,
        group: ScanGroup,
        client: Client,
        started: float,
        stamp: float,
        responses: list[Response] | None,
        error: BaseException | None,
    ) -> None:
        plan = group.plan
        assert plan is not None
        values: tuple[Value, ...] | None = None
        read: dict[str, Value] | None = None
        bad: dict[str, str] = {}
        if responses is not None:
            try:
                values, read = _decode(client, plan, responses, bad)
            except FinsError as exc:
                error = exc
        elif isinstance(error, EndCodeError):
            add_addressing_hint(error, client.dest, client.session.source)
        self._handover(group, self._scanned(group, started, stamp, values, read, bad, error))

    def _handover(self, group: ScanGroup, snapshot: Snapshot | None) -> None:
        """A callback scan's snapshot to the buffer, or, if the buffer is full, to the
        group's task to wait for room; the scan is over (IDLE) otherwise."""
        if snapshot is not None and not self._channel.send_nowait(snapshot):
            group._enter(ScanState.DELIVERING)  # full: the group's task waits for room
            group._undelivered = snapshot
            group._wake.set()
            return
        group._enter(ScanState.IDLE)
        if self._hooks is not None:
            self._scan_done(group)

    async def scan_once(self, group: ScanGroup) -> Snapshot | None:
        """Run one scan of ``group`` now; the snapshot (``None`` if nothing to deliver)."""
        started = self._now()
        stamp = time.time()
        group.scans += 1
        error: FinsError | None = None
        read: dict[str, Value] | None = None
        bad: dict[str, str] = {}  # tags whose words are no value of their type
        try:
            # Borrowed without ``async with``: a ready session is lent with no coroutine. The
            # group keeps its lease between scans (taken while in use: scan_once may run
            # beside the group's own scan).
            lease = group._lease
            if lease is None:
                lease = self.pool._lease(group.url, group.timeout)
            else:
                group._lease = None
            client = lease.borrow_ready() or await lease.borrow()
            try:
                plan = group.plan
                if plan is None:
                    plan = group.plan = client.compile_tags(group.tags)
                read = await client.read_tags(plan, timeout=group.timeout, errors=bad)
            finally:
                lease.release()
                if group._lease is None:
                    group._lease = lease
        except FinsError as exc:
            error = exc
        return self._scanned(group, started, stamp, None, read, bad, error)

    def _scanned(
        self,
        group: ScanGroup,
        started: float,
        stamp: float,
        values: tuple[Value, ...] | None,
        read: dict[str, Value] | None,
        bad: dict[str, str],
        exc: BaseException | None,
    ) -> Snapshot | None:
        """The snapshot of a scan that read ``values`` (in the plan's tag order) or ``read``
        (by name; ``bad``: the tags that are no value of their type) or failed with
        ``exc``, counted and logged; ``None`` if nothing to deliver."""
        error: str | None = None
        waited = self._waited(group, exc is not None) if group._missed_unlogged else ""
        if exc is not None:
            group.errors += 1
            error = f"{type(exc).__name__}: {exc}"
            if group._failing is None:
                logger.warning(
                    "scan group %s: scans of %s fail: %s%s",
                    group.name,
                    group.url,
                    error,
                    waited,
                    extra={"group": group.name, "endpoint": group.url},
                )
            group._failing = error
        elif group._failing is not None:
            group._failing = None
            logger.info(
                "scan group %s: scans of %s succeed again",
                group.name,
                group.url,
                extra={"group": group.name, "endpoint": group.url},
            )
        group.last_duration = self._now() - started
        if error is None and not bad:  # the usual scan: every tag read
            plan = group.plan
            assert plan is not None
            tag_names = plan.tag_names
            if values is None:
                assert read is not None
                values = tuple([read[name] for name in tag_names.names])
            return self._good(group, stamp, values, tag_names)
        last = group._last
        readings: dict[str, TagReading] = {}
        changed = set()
        for name in group.tags:
            previous = last.get(name)
            failed = error if error is not None else bad.get(name)
            if failed is None:
                assert read is not None
                value: Value | None = read[name]
                reading = _reading(value, _GOOD, stamp, None)
            elif previous is not None and previous.value is not None:
                value = previous.value
                reading = _reading(value, _STALE, previous.timestamp, failed)
            else:
                value = None
                reading = _reading(None, _ERROR, None, failed)
            # Changed unless (value, quality) equal the previous ones (as tuples compare).
            if (
                previous is None
                or not (previous.value is value or previous.value == value)
                or previous.quality is not reading.quality
            ):
                changed.add(name)
            readings[name] = reading
        group._last, group._last_good = readings, None
        return self._deliver(group, stamp, readings, changed, error)

    def _good(
        self, group: ScanGroup, stamp: float, values: tuple[Value, ...], tag_names: TagNames
    ) -> Snapshot | None:
        """The snapshot of a scan in which every tag was read (``values`` in the plan's tag
        order, named by ``tag_names``; the scan counted and logged by :meth:`_scanned`)."""
        changed: AbstractSet[str] = _UNCHANGED
        before = group._last_good
        names = tag_names.names
        if before is not None:  # so was the last one: compare values only
            if values != before:  # (equal tuples: nothing changed, found in one C call)
                changed = {
                    names[i]
                    for i, (old, new) in enumerate(zip(before, values, strict=True))
                    if not (old is new or old == new)
                }
        else:
            changed = set()
            last = group._last
            for name, got in zip(names, values, strict=True):
                previous = last.get(name)
                if (
                    previous is None
                    or previous.quality is not _GOOD
                    or not (previous.value is got or previous.value == got)
                ):
                    changed.add(name)
        good: GoodReadings = _new(GoodReadings)  # a reading is made when asked for
        good._names = tag_names
        good._values = values
        good._stamp = stamp
        group._last, group._last_good = good, values
        return self._deliver(group, stamp, good, changed, None)

    def _deliver(
        self,
        group: ScanGroup,
        stamp: float,
        readings: Mapping[str, TagReading],
        changed: AbstractSet[str],
        error: str | None,
    ) -> Snapshot | None:
        """The scan's snapshot (with ``changes_only``: its changed tags, None if none)."""
        if self.changes_only:
            if not changed:
                return None
            readings = {name: readings[name] for name in changed}
        snapshot: Snapshot = _new(Snapshot)  # Snapshot(...) at a third of the cost
        _set(
            snapshot,
            "__dict__",
            {
                "group": group.name,
                "endpoint": group.url,
                "scan": group.scans,
                "timestamp": stamp,
                "duration": group.last_duration,
                "readings": readings,
                "changed": frozenset(changed) if changed else _UNCHANGED,
                "error": error,
            },
        )
        return snapshot


_GOOD, _STALE, _ERROR = Quality.GOOD, Quality.STALE, Quality.ERROR
_NORMAL = EndCode(0)
#: Scan times this close are due now: event loops round timers (uvloop to 1 ms), and a timer
#: that fires a little early must not make the timer task spin until the exact time.
_TIMER_SLACK = 0.001
_NONE = object()
_UNCHANGED: frozenset[str] = frozenset()


class GoodReadings(Mapping[str, TagReading]):
    """The readings of a scan in which every tag was read: the values in the tag list's
    order, with the names (and their positions) shared by every scan of the plan; a
    reading is built when looked up, so a scan nobody looks into costs no object per tag.
    ``GoodReadings({name: value, ...}, stamp)`` builds one from a dict."""

    __slots__ = ("_names", "_stamp", "_values")

    _names: TagNames
    _values: tuple[Value, ...]
    _stamp: float

    def __init__(self, values: Mapping[str, Value], stamp: float) -> None:
        self._names = TagNames(tuple(values))
        self._values = tuple(values.values())
        self._stamp = stamp

    def __getitem__(self, name: str) -> TagReading:
        return _reading(self._values[self._names.index[name]], _GOOD, self._stamp, None)

    def __iter__(self) -> Iterator[str]:
        return iter(self._names.names)

    def __len__(self) -> int:
        return len(self._values)

    def __contains__(self, name: object) -> bool:
        return name in self._names.index

    def __repr__(self) -> str:
        return repr(dict(self.items()))

    def values_by_name(self) -> dict[str, Value]:
        """``{name: value}`` without a reading per tag."""
        return dict(zip(self._names.names, self._values, strict=True))


def _one_frame(plan: ReadPlan) -> OneFrame | tuple[()]:
    """A plan of one frame: its command and the decoder of its reply (``None``: decoded
    tag by tag); ``()`` for a plan of several frames."""
    commands = plan.scan_commands()[0]
    if len(commands) != 1 or plan.multiple:
        return ()
    return commands[0], plan.frame_decoder()


def _decode(
    client: Client, plan: ReadPlan, responses: list[Response], bad: dict[str, str]
) -> tuple[tuple[Value, ...] | None, dict[str, Value] | None]:
    """A callback scan's values from its responses (the plan's 0101 runs, then its 0104
    frames), as :meth:`Client.read_tags` decodes them: in tag order where the plan decodes
    in bulk, else by name (``bad``: the tags that are no value of their type)."""
    n_runs = len(plan.runs)
    multi: list[Sequence[int]] = []
    if n_runs == 1 and not plan.multiple:  # the usual small tag list: one frame
        run_words = [plan.run_words(0, responses[0].data)]
    else:
        run_words = [plan.run_words(i, responses[i].data) for i in range(n_runs)]
    if plan.multiple:
        _, requests = plan.scan_commands()
        multi = [
            [item.value for item in m.decode_response(response.data).items]
            for m, response in zip(requests, responses[n_runs:], strict=True)
        ]
    client.last_end_code = responses[-1].end_code
    values = plan.decode_values(run_words, multi)
    if values is not None:
        return values, None
    return None, plan.decode(run_words, multi, bad)


_new = object.__new__
_set = object.__setattr__


def _reading(
    value: Value | None, quality: Quality, timestamp: float | None, error: str | None
) -> TagReading:
    """``TagReading(...)`` at a third of the cost (fills the instance dict in one step)."""
    reading: TagReading = _new(TagReading)
    _set(
        reading,
        "__dict__",
        {"value": value, "quality": quality, "timestamp": timestamp, "error": error},
    )
    return reading
