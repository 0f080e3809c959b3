"""The virtual-time loop reports a world that cannot move instead of running for ever."""

from __future__ import annotations

import asyncio

import pytest

from .loop import STILL_LIMIT, VirtualTimeLoop, WorldStuck


def test_a_task_that_never_waits_is_reported_not_run_for_ever() -> None:
    """A task that yields with no time passing, over and over (seed 30145: a pool task
    whose borrow was refused at once, with no think time), kept virtual time at one
    instant for ever: the harness ran > 6 min of wall time and never ended."""
    loop = VirtualTimeLoop()
    turns = 0

    async def spin() -> None:
        nonlocal turns
        await asyncio.sleep(0.5)
        while True:
            turns += 1
            await asyncio.sleep(0)

    try:
        with pytest.raises(WorldStuck, match=r"stands still at 0\.5000 s"):
            loop.run_until_complete(spin())
        assert loop.time() == 0.5
        assert STILL_LIMIT <= turns <= STILL_LIMIT + 2
    finally:
        loop.close()


def test_a_world_waiting_on_nothing_is_reported() -> None:
    loop = VirtualTimeLoop()
    try:
        with pytest.raises(WorldStuck, match="no timer set"):
            loop.run_until_complete(asyncio.Event().wait())
    finally:
        loop.close()


def test_time_moves_to_the_next_timer_exactly() -> None:
    loop = VirtualTimeLoop()
    try:
        loop.run_until_complete(asyncio.sleep(10.25))
        assert loop.time() == 10.25
    finally:
        loop.close()
