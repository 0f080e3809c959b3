"""A wake-up signal and a bounded channel for the Poller, lighter than anyio's memory streams.

anyio's memory object streams check for cancellation and yield to the event loop on every
``receive`` and allocate per waiter; the poller hands over one snapshot per scan, so both
are paid per scan. Here, under asyncio a waiter is one bare future (set from the loop's own
thread, the only one that touches these objects); under other backends an ``anyio.Event``.
Cancellation of a waiting task works as with any await (the future is dropped).
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator
from typing import Any, Generic, TypeVar

import anyio

from .transport.base import is_asyncio

T = TypeVar("T")


class Wake:
    """One task waits (:meth:`wait`) until another calls :meth:`set`; a ``set`` with no one
    waiting is kept for the next ``wait``."""

    __slots__ = ("_loop", "_pending", "_waiter")

    def __init__(self) -> None:
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pending = False
        self._waiter: Any = None

    def bind(self) -> None:
        """Use the running asyncio loop's futures (call from inside the loop)."""
        self._loop = asyncio.get_running_loop() if is_asyncio() else None

    async def wait(self) -> None:
        if self._pending:
            self._pending = False
            return
        loop = self._loop
        if loop is not None:
            fut = self._waiter = loop.create_future()
            try:
                await fut
            finally:
                self._waiter = None
        else:
            event = self._waiter = anyio.Event()
            try:
                await event.wait()
            finally:
                self._waiter = None
        self._pending = False

    def set(self) -> None:
        waiter = self._waiter
        if waiter is None:
            self._pending = True
        elif self._loop is not None:
            if not waiter.done():
                waiter.set_result(None)
        else:
            waiter.set()

    @property
    def waiting(self) -> bool:
        return self._waiter is not None


class Channel(Generic[T]):
    """A bounded FIFO: producers wait for room when it is full (backpressure, first come
    first served); the consumer iterates it and waits only when it is empty. :meth:`close`
    ends the iteration once the queued items are taken.

    A waiting producer's item is queued by the consumer as soon as there is room for it,
    so items keep the order their producers started waiting in, whatever order the event
    loop then resumes the producers in. (A producer cancelled after that point has sent.)
    """

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"channel size must be at least 1, got {size}")
        self.size = size
        self._items: deque[T] = deque()
        #: Producers waiting, in order: [their wake-up, their item, whether it was queued].
        self._room: deque[list[Any]] = deque()
        self._ready = Wake()  # the consumer waiting for an item
        self.closed = False

    def bind(self) -> None:
        """Use the running loop's futures (call from inside it)."""
        self._ready.bind()

    def send_nowait(self, item: T) -> bool:
        """Queue ``item`` if there is room and no producer waits before it (True)."""
        if self.closed:
            raise anyio.ClosedResourceError
        if self._room or len(self._items) >= self.size:
            return False
        self._items.append(item)
        self._ready.set()
        return True

    async def send(self, item: T) -> None:
        """Queue ``item``, waiting for room first if the channel is full."""
        if self.send_nowait(item):
            return
        wake = Wake()
        wake.bind()
        entry = [wake, item, False]
        self._room.append(entry)
        try:
            await wake.wait()
        finally:
            if not entry[2]:  # cancelled while waiting (or closed): not sent
                for i, waiting in enumerate(self._room):
                    if waiting is entry:
                        del self._room[i]
                        break
        if not entry[2]:  # woken by close()
            raise anyio.ClosedResourceError

    def close(self) -> None:
        """No more items; the waiting producers fail with ``ClosedResourceError``."""
        self.closed = True
        self._ready.set()
        while self._room:
            self._room.popleft()[0].set()

    def __aiter__(self) -> AsyncIterator[T]:
        return self

    async def __anext__(self) -> T:
        items = self._items
        while not items:
            if self.closed:
                raise StopAsyncIteration
            await self._ready.wait()
        item = items.popleft()
        room = self._room
        if room:  # the first waiting producer's item takes the place
            entry = room.popleft()
            items.append(entry[1])
            entry[2] = True
            entry[0].set()
        return item
