"""A virtual-time asyncio event loop: the simulation's one clock and its one scheduler.

``loop.time()`` is virtual. The selector never blocks: when nothing is ready it advances the
virtual clock by exactly the timeout asyncio asked for (the time to the next timer), so a
10 s outage takes as long as the callbacks it runs. asyncio runs ready callbacks first in,
first out, and orders timers by time and then by the order they were made, so a run depends
on nothing but what the code does: the same seed gives the same run.

Why asyncio and not trio's ``MockClock(autojump_threshold=0)``: trio shuffles the order in
which it runs a batch of ready tasks (on purpose, to shake out scheduling assumptions) with a
random generator private to its run loop, so two trio runs of one seed need not interleave
alike, and seeding it means touching trio's internals. The asyncio loop below is public API
only (a selector and ``time()``), FIFO, and replays bit for bit. The session code is the
same under both backends (anyio), and the trio backend keeps its own tests on MockClock.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import selectors
from typing import Any


class WorldStuck(RuntimeError):
    """Nothing is ready and no timer is set: every task waits for something that cannot
    come (a deadlock of the code under test, never a quiet network: the world keeps timers);
    or virtual time stands still for :data:`STILL_LIMIT` turns of the loop (a busy loop: a
    task that yields without waiting, over and over, in the code under test or the
    world's)."""


#: Turns of the loop at one virtual instant after which the world is stuck in a busy loop
#: (a burst of 255 requests answered at once takes a few thousand).
STILL_LIMIT = 200_000


class _VirtualSelector(selectors.DefaultSelector):
    """Polls the (few, local) file descriptors without blocking; advances the clock instead
    of sleeping."""

    def __init__(self, clock: VirtualClock) -> None:
        super().__init__()
        self._clock = clock
        self._still = 0

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        events = super().select(0)
        if events:
            return events
        if timeout is None:
            raise WorldStuck("no callback ready and no timer set: the world can never move")
        before = self._clock.now
        if timeout > 0:
            self._clock.now += timeout
        if self._clock.now != before:
            self._still = 0
        else:
            self._still += 1
            if self._still > STILL_LIMIT:
                raise WorldStuck(
                    f"virtual time stands still at {self._clock.now:.4f} s for"
                    f" {STILL_LIMIT:,} turns of the loop: a task yields without ever waiting"
                )
        return []


class _Timer(asyncio.TimerHandle):
    """A timer ordered by time and then by the order timers were made: asyncio's own compare
    only their times, so timers due at one instant run in an order that depends on the
    heap's shape, that is on every other timer made so far (a replayed schedule, which
    plans its faults at the start rather than one after another, ran them otherwise)."""

    __slots__ = ("_order",)

    def __init__(
        self, when: float, order: int, callback: Any, args: Any, loop: Any, context: Any
    ) -> None:
        super().__init__(when, callback, args, loop, context)
        self._order = order

    def __lt__(self, other: object) -> bool:
        if isinstance(other, _Timer):
            mine, theirs = self._when, other._when  # type: ignore[attr-defined]
            return mine < theirs or (mine == theirs and self._order < other._order)
        return NotImplemented


class VirtualClock:
    """The virtual time, in seconds from 0."""

    def __init__(self) -> None:
        self.now = 0.0


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An asyncio loop on :class:`VirtualClock` time (see the module's docstring)."""

    def __init__(self) -> None:
        self.clock = VirtualClock()
        super().__init__(_VirtualSelector(self.clock))
        self._clock_resolution = 1e-9

    def time(self) -> float:
        return self.clock.now

    def call_at(  # type: ignore[override]
        self, when: float, callback: Any, *args: Any, context: Any = None
    ) -> asyncio.TimerHandle:
        # BaseEventLoop.call_at with the timer above (its heap, ``_scheduled``, is asyncio's)
        self._check_closed()  # type: ignore[attr-defined]
        timer = _Timer(when, next(self._made), callback, args, self, context)
        heapq.heappush(self._scheduled, timer)  # type: ignore[attr-defined]
        timer._scheduled = True  # type: ignore[attr-defined]
        return timer

    def default_exception_handler(self, context: dict[str, Any]) -> None:
        # An exception nobody retrieved is a finding, not noise: keep it for the checker.
        self.unhandled.append(context)

    unhandled: list[dict[str, Any]]
    _made: itertools.count[int]

    def __new__(cls, *args: Any, **kwargs: Any) -> VirtualTimeLoop:
        self = super().__new__(cls)
        self.unhandled = []
        self._made = itertools.count()
        return self
