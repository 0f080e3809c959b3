"""A per-endpoint circuit breaker: fail fast on a dead PLC, one probe tests the link.

After ``threshold`` calls in a row fail with no answer (timeout, lost or refused link), the
breaker opens: calls fail at once with :class:`~aiofins.protocol.errors.CircuitOpen`, nothing
sent, except one probe at a time, let through once a jittered pause has passed. A call that
gets any answer (an error end code included) closes it. The pause grows while probes fail
(doubling from ``cooldown[0]``, capped by ``cooldown[1]`` and by the probing call's own
timeout, so a PLC that answers again is found within about one timeout of a caller's).
"""

from __future__ import annotations

import enum
import logging
import math
import random
from typing import TYPE_CHECKING

from ..protocol.errors import CircuitOpen, ConnectionLost, FinsTimeout
from ..protocol.header import FinsAddress
from .batch import raise_after_a_turn
from .link import InBackoff
from .slots import SlotTimeout

if TYPE_CHECKING:
    from .response import SessionStats

logger = logging.getLogger("aiofins.session")


class BreakerState(enum.Enum):
    """The breaker of one endpoint."""

    #: Calls go through; consecutive failures are counted.
    CLOSED = "closed"
    #: Too many failures in a row: calls fail at once until the next probe may go.
    OPEN = "open"
    #: One call (the probe) is testing the link; the others fail at once meanwhile.
    HALF_OPEN = "half_open"


class CircuitBreaker:
    """Counts failures in a row and decides whether a call may go (see the module)."""

    __slots__ = ("cooldown", "failures", "pause", "probe_at", "state", "threshold", "trips")

    def __init__(self, threshold: int, cooldown: tuple[float, float]) -> None:
        #: Failures in a row that open the breaker (0: never).
        self.threshold = threshold
        self.cooldown = cooldown
        self.state = BreakerState.CLOSED
        self.failures = 0
        #: How often the breaker opened.
        self.trips = 0
        self.pause = 0.0
        self.probe_at = 0.0

    def admit(self, now: float) -> float:
        """Whether a call may go now: ``0.0`` if it may (in ``OPEN`` it becomes the probe),
        else the seconds until the next probe may go (``inf`` while a probe is in flight)."""
        state = self.state
        if state is BreakerState.CLOSED:
            return 0.0
        if state is BreakerState.HALF_OPEN:
            return float("inf")
        wait = self.probe_at - now
        if wait > 0:
            return wait
        self.state = BreakerState.HALF_OPEN
        return 0.0

    def succeeded(self) -> bool:
        """A call got an answer; whether this closed an open breaker."""
        self.failures = 0
        if self.state is BreakerState.CLOSED:
            return False
        self.state = BreakerState.CLOSED
        self.pause = 0.0
        return True

    def failed(self, now: float, timeout: float) -> bool:
        """A call got no answer (``timeout``: that call's); whether this opened the breaker."""
        self.failures += 1
        state = self.state
        if state is BreakerState.CLOSED:
            if not self.threshold or self.failures < self.threshold:
                return False
            self.trips += 1
            opened = True
        else:
            opened = False
        low, high = self.cooldown
        self.pause = min(high, timeout, max(low, self.pause * 2))
        self.probe_at = now + self.pause * random.uniform(0.5, 1.0)
        self.state = BreakerState.OPEN
        return opened

    def released(self) -> None:
        """A probe ended without an outcome (cancelled, no slot): another may go."""
        if self.state is BreakerState.HALF_OPEN:
            self.state = BreakerState.OPEN


# The session's side: what a call does at the breaker (its start, its end), logged.


def rejection(
    breaker: CircuitBreaker, stats: SessionStats, dest: FinsAddress, where: str, now: float
) -> CircuitOpen | None:
    """Whether a call to ``dest`` (via ``where``) may go through the breaker at ``now`` (the
    session's clock): ``None`` if so (the probe, while the breaker is open), else the
    :class:`CircuitOpen` to fail it with at once (counted in ``stats.breaker_rejects``)."""
    wait = breaker.admit(now)
    if not wait:
        return None
    stats.breaker_rejects += 1
    if wait == math.inf:
        how = "a probe is testing whether it answers again"
        wait = 0.0
    else:
        how = f"the next probe in {wait:.2f} s"
    return CircuitOpen(
        f"{dest} via {where} failed {breaker.failures} calls in a row: failing fast ({how})",
        retry_after=wait,
    )


async def admit_call(
    breaker: CircuitBreaker, stats: SessionStats, dest: FinsAddress, where: str, now: float
) -> None:
    """Let a call through the breaker, or fail it (see :func:`rejection`) after a turn of
    the event loop."""
    error = rejection(breaker, stats, dest, where, now)
    if error is not None:
        await raise_after_a_turn(error)


def call_answered(breaker: CircuitBreaker, where: str) -> None:
    """A call got an answer (any end code): the breaker closes (logged if it was open)."""
    if breaker.succeeded():
        logger.info("%s answers again: circuit breaker closed", where, extra={"endpoint": where})


def call_ended(
    breaker: CircuitBreaker, exc: BaseException, timeout: float, where: str, now: float
) -> None:
    """A call raised ``exc`` at ``now`` (the session's clock; its ``timeout`` was that): a
    failure of the link (no answer,
    link lost) counts towards opening the breaker (logged when it opens); a call failed
    before it was sent (slot or SID wait, open breaker, reconnect backoff) or cancelled
    only gives back the probe's turn."""
    if isinstance(exc, (FinsTimeout, ConnectionLost)) and not isinstance(
        exc, (SlotTimeout, CircuitOpen, InBackoff)
    ):
        if breaker.failed(now, timeout):
            logger.warning(
                "%s: %d calls in a row got no answer: circuit breaker open, failing fast "
                "while a probe tests the link",
                where,
                breaker.failures,
                extra={"endpoint": where},
            )
    else:
        breaker.released()
