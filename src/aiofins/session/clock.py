"""The session's one clock: where every time the session reads comes from.

Every part of a session (the link, its SID spaces, the breaker, the deadline watcher,
batches, matching) reads the time through the one callable the session hands it
(:class:`Clock`), never :func:`time.monotonic` itself. By default that callable is the
running event loop's clock, so under trio's ``MockClock`` (or an asyncio loop with virtual
time) the whole session runs on virtual time: a 10 s outage takes milliseconds and a timing
assertion is exact. A driver without an event loop passes its own (``Session(clock=...)``).

:func:`backend_clocks` chooses, under the running backend:

- asyncio's own loops: :func:`time.monotonic` itself, which is what their ``loop.time()``
  returns (the same values, without a Python call per reading);
- uvloop: :func:`time.monotonic` too. uvloop's ``loop.time()`` is libuv's loop time, read
  once per loop turn at 1 ms resolution: a round trip to a PLC on the same LAN (0.2-2 ms)
  would read 0 or 1 ms. It is the same ``CLOCK_MONOTONIC``, read fresh; the watcher's timer
  is then set by the difference (:attr:`Clocks.direct` is false);
- any other asyncio loop (a virtual-time loop, e.g. looptime's): its ``loop.time``;
- trio: the run's clock (``trio.lowlevel.current_clock().current_time``: what
  :func:`trio.current_time` reads, at half its cost and a seventh of
  ``anyio.current_time``'s; ``MockClock`` under tests);
- any other backend: :func:`anyio.current_time`.

Round trips (the adaptive retransmission timeout, latency statistics and hooks) are
measured on that same clock: a measurement on another clock would be wall time under a
virtual clock, and the retransmission timeout would no longer match the timers it sets.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Callable
from time import monotonic
from typing import NamedTuple

import anyio

#: A clock: seconds as a float, never going back.
Clock = Callable[[], float]


class Clocks(NamedTuple):
    """The clocks of a running session."""

    #: What the session reads: deadlines, round trips, quarantines, backoffs.
    session: Clock
    #: The backend's own clock, which its timers (``loop.call_at``, a cancel scope's
    #: deadline) are set in.
    timer: Clock
    #: Whether a time of :attr:`session` may be given to the timers as it is (else it is
    #: set by the difference: ``timer() + (at - session())``).
    direct: bool


def backend_clocks(clock: Clock | None = None) -> Clocks:
    """The clocks of a session entered now, under the running backend (see the module);
    ``clock``: the one its user passed, if any."""
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        loop = None
    if loop is not None:
        timer: Clock = loop.time
        kind = type(loop).time
        own = kind is asyncio.BaseEventLoop.time
        uvloop = sys.modules.get("uvloop")
        precise: Clock = timer
        if own or (uvloop is not None and kind is uvloop.Loop.time):
            precise = monotonic
        if clock is None:
            clock = precise
        return Clocks(clock, timer, clock is timer or (own and clock is monotonic))
    trio = sys.modules.get("trio")
    if trio is not None and trio.lowlevel.in_trio_run():
        # The run's clock itself (MockClock's under tests): what trio.current_time reads,
        # without the look-up of the run on every reading.
        timer = trio.lowlevel.current_clock().current_time
    else:  # pragma: no cover - anyio's other backends, if any
        timer = anyio.current_time
    if clock is None:
        clock = timer
    return Clocks(clock, timer, clock is timer)
