"""Counting event-loop passes: how often other tasks got to run while a block ran."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio


class LoopPasses:
    """``count``: the turns a task that only yields got since the block started."""

    def __init__(self) -> None:
        self.count = 0


@asynccontextmanager
async def counting_loop_passes() -> AsyncIterator[LoopPasses]:
    """Run the block next to a task that yields and counts each turn it gets."""
    passes = LoopPasses()

    async def ticker() -> None:
        while True:
            await anyio.sleep(0)
            passes.count += 1

    async with anyio.create_task_group() as tg:
        tg.start_soon(ticker)
        await anyio.sleep(0)
        passes.count = 0
        try:
            yield passes
        finally:  # at once: the ticker gets no turn after the block
            tg.cancel_scope.cancel()
