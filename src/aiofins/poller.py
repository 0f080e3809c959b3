"""A polling engine: scan groups over one or many PLCs, delivered as timestamped snapshots.

Each scan group reads its tag list (compiled once into the fewest frames, see
:mod:`aiofins.tags`) from one endpoint every ``interval`` seconds, in its own task, through a
:class:`~aiofins.pool.Pool`, so a slow or dead PLC never delays the others. Scans are
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

import logging
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from types import TracebackType
from typing import TYPE_CHECKING

import anyio
from anyio.abc import TaskGroup
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from .endpoint import parse_endpoint
from .hooks import EventHooks, ScanDone
from .pool import backend_sleep, event_loop_clock
from .protocol.errors import CommandError, FinsError
from .protocol.values import Value
from .tags import ReadPlan, parse_tag

if TYPE_CHECKING:
    from .pool import Pool

logger = logging.getLogger("aiofins.poller")

#: Seconds between two warnings about one group's missed scans (the count says how many).
MISSED_WARNING_INTERVAL = 60.0


class Quality(Enum):
    GOOD = "good"
    STALE = "stale"
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
        return {name: r.value for name, r in self.readings.items()}


@dataclass
class ScanGroup:
    """A tag list read from one endpoint every ``interval`` seconds, with its counters."""

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
    _last: dict[str, TagReading] = field(default_factory=dict)
    #: The error of the last failed scan while scans fail (logged once per outage).
    _failing: str | None = None
    #: Missed scans not yet warned about, and when the last warning was logged.
    _missed_unlogged: int = 0
    _missed_logged_at: float = -math.inf


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
        send, receive = anyio.create_memory_object_stream[Snapshot](buffer)
        self._send: MemoryObjectSendStream[Snapshot] = send
        self._receive: MemoryObjectReceiveStream[Snapshot] = receive
        self._tg: TaskGroup | None = None
        self._now = anyio.current_time
        self._sleep: Callable[[float], Awaitable[None]] = anyio.sleep

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
            self._tg.start_soon(self._run_group, group)
        return group

    async def __aenter__(self) -> Poller:
        self._now = event_loop_clock()
        self._sleep = backend_sleep()
        self._tg = anyio.create_task_group()
        await self._tg.__aenter__()
        for group in self.groups.values():
            self._tg.start_soon(self._run_group, group)
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
            self._send.close()
            self._receive.close()

    def __aiter__(self) -> AsyncIterator[Snapshot]:
        return self._receive.__aiter__()

    async def _run_group(self, group: ScanGroup) -> None:
        clock, sleep = self._now, self._sleep
        next_at = clock()
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
                now = clock()
                if now < next_at:
                    await sleep(next_at - now)
                snapshot = await self.scan_once(group)
                if snapshot is not None:
                    try:  # room in the buffer: no extra trip through the event loop
                        self._send.send_nowait(snapshot)
                    except anyio.WouldBlock:  # full: wait for the consumer (backpressure)
                        await self._send.send(snapshot)
                next_at += group.interval
                now = clock()
                skipped = 0
                if now > next_at:
                    skipped = math.floor((now - next_at) / group.interval) + 1
                    group.missed += skipped
                    next_at += skipped * group.interval
                    self._missed(group, skipped, now)
                hooks = self._hooks
                if hooks is not None and hooks.scan_done:
                    hooks.emit(
                        hooks.scan_done,
                        ScanDone(
                            group.name, group.scans, group.last_duration, skipped, group._failing
                        ),
                    )
        finally:
            logger.info(
                "scan group %s stopped after %d scans (%d failed, %d missed)",
                group.name,
                group.scans,
                group.errors,
                group.missed,
                extra={"group": group.name, "endpoint": group.url},
            )

    def _missed(self, group: ScanGroup, skipped: int, now: float) -> None:
        """Count missed scans; warn at the first and then at most once a minute per group."""
        group._missed_unlogged += skipped
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

    async def scan_once(self, group: ScanGroup) -> Snapshot | None:
        """Run one scan of ``group`` now; the snapshot (``None`` if nothing to deliver)."""
        now = self._now
        started = now()
        stamp = time.time()
        group.scans += 1
        error: str | None = None
        values: dict[str, Value] = {}
        bad: dict[str, str] = {}  # tags whose words are no value of their type
        try:
            # Borrowed without ``async with``: a ready session is lent with no coroutine.
            lease = self.pool._lease(group.url, group.timeout)
            client = lease.borrow_ready() or await lease.borrow()
            try:
                plan = group.plan
                if plan is None:
                    plan = group.plan = client.compile_tags(group.tags)
                values = await client.read_tags(plan, timeout=group.timeout, errors=bad)
            finally:
                lease.release()
        except FinsError as exc:
            group.errors += 1
            error = f"{type(exc).__name__}: {exc}"
            if group._failing is None:
                logger.warning(
                    "scan group %s: scans of %s fail: %s",
                    group.name,
                    group.url,
                    error,
                    extra={"group": group.name, "endpoint": group.url},
                )
            group._failing = error
        else:
            if group._failing is not None:
                group._failing = None
                logger.info(
                    "scan group %s: scans of %s succeed again",
                    group.name,
                    group.url,
                    extra={"group": group.name, "endpoint": group.url},
                )
        group.last_duration = now() - started
        readings: dict[str, TagReading] = {}
        changed: set[str] = set()
        last = group._last
        if error is None and not bad:  # the usual scan: every tag read, in the tag list's order
            for name, read in values.items():
                previous = last.get(name)
                readings[name] = _reading(read, _GOOD, stamp, None)
                if (
                    previous is None
                    or previous.quality is not _GOOD
                    or not (previous.value is read or previous.value == read)
                ):
                    changed.add(name)
            group._last = readings
            return self._deliver(group, stamp, readings, changed, error)
        for name in group.tags:
            previous = last.get(name)
            failed = error if error is not None else bad.get(name)
            if failed is None:
                value: Value | None = values[name]
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
        group._last = readings
        return self._deliver(group, stamp, readings, changed, error)

    def _deliver(
        self,
        group: ScanGroup,
        stamp: float,
        readings: dict[str, TagReading],
        changed: set[str],
        error: str | None,
    ) -> Snapshot | None:
        """The scan's snapshot (with ``changes_only``: its changed tags, None if none)."""
        if self.changes_only:
            if not changed:
                return None
            readings = {name: readings[name] for name in changed}
        return _snapshot(
            group.name,
            group.url,
            group.scans,
            stamp,
            group.last_duration,
            readings,
            frozenset(changed),
            error,
        )


_GOOD, _STALE, _ERROR = Quality.GOOD, Quality.STALE, Quality.ERROR
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


def _snapshot(
    group: str,
    endpoint: str,
    scan: int,
    timestamp: float,
    duration: float,
    readings: Mapping[str, TagReading],
    changed: frozenset[str],
    error: str | None,
) -> Snapshot:
    """``Snapshot(...)``, built the way :func:`_reading` builds a reading."""
    snapshot: Snapshot = _new(Snapshot)
    _set(
        snapshot,
        "__dict__",
        {
            "group": group,
            "endpoint": endpoint,
            "scan": scan,
            "timestamp": timestamp,
            "duration": duration,
            "readings": readings,
            "changed": changed,
            "error": error,
        },
    )
    return snapshot
