"""Hypothesis drives the same harness: rules inject faults and let virtual time pass, every
invariant is checked after each rule and at the end (recovery, quiescence, leaks). A failure
shrinks to a short fault schedule (hypothesis prints the rules it took)."""

from __future__ import annotations

from contextlib import AbstractContextManager
from dataclasses import replace

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from .scenarios import BASE
from .world import EXPOSED, KINDS, UNFIXED, World, suspect

#: Two units (one relaying to network 2), every path: connect(), FINS/TCP, Pool, Poller.
CONFIG = replace(
    BASE,
    units=2,
    relays=frozenset({2}),
    connect_sessions=1,
    connect_tasks=4,
    max_in_flight=5,
    tcp_sessions=1,
    pool_tasks=2,
    poller_groups=1,
    think=0.005,
)


class FaultySchedule(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.world = World(22, 10**9, manual=True, config=CONFIG)
        self.context: AbstractContextManager[None] = self.world.context()
        self.context.__enter__()
        self.world.start()
        self.open = True

    @rule(
        kind=st.sampled_from(KINDS),
        unit=st.integers(1, CONFIG.units),
        duration=st.floats(0.05, 1.5),
        p=st.sampled_from((0.3, 1.0)),
    )
    def fault(self, kind: str, unit: int, duration: float, p: float) -> None:
        if kind == "delay":
            p *= 2 * CONFIG.timeout
        if self.world.violation is None:  # (a world that failed has stopped)
            self.world.inject(kind, unit, duration, p)

    @rule(seconds=st.floats(0.01, 2.0))
    def wait(self, seconds: float) -> None:
        self.world.advance(seconds)

    @invariant()
    def every_invariant_holds(self) -> None:
        _check(self.world)

    def teardown(self) -> None:
        world = self.world
        try:
            if world.violation is None:
                world.finish()
        finally:
            self.context.__exit__(None, None, None)
        _check(world)


def _check(world: World) -> None:
    """No violation, or one of a defect not yet fixed on main (world.UNFIXED) or of an
    exposed kind (world.EXPOSED)."""
    if world.violation is not None:
        result = world.result()
        assert suspect(result) in UNFIXED | EXPOSED, result.reproducer()


FaultySchedule.TestCase.settings = settings(
    max_examples=10,
    stateful_step_count=10,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
TestFaultySchedule = FaultySchedule.TestCase
