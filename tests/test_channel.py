"""The Poller's wake-up signal and bounded channel (asyncio, uvloop and trio)."""

from __future__ import annotations

import anyio
import pytest

from aiofins._channel import Channel, Wake

pytestmark = pytest.mark.anyio


async def test_a_set_before_the_wait_is_kept(anyio_backend: object) -> None:
    wake = Wake()
    wake.bind()
    wake.set()
    with anyio.fail_after(10):  # a hang guard, not a time limit
        await wake.wait()  # returns at once
    got: list[str] = []

    async def waiter() -> None:
        await wake.wait()
        got.append("woken")

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await anyio.wait_all_tasks_blocked()
        assert wake.waiting and got == []
        wake.set()
    assert got == ["woken"]


async def test_backpressure_order_and_close(anyio_backend: object) -> None:
    channel: Channel[int] = Channel(2)
    channel.bind()
    assert channel.send_nowait(1) and channel.send_nowait(2)
    assert not channel.send_nowait(3)  # full
    sent: list[int] = []

    async def producer(n: int) -> None:
        await channel.send(n)
        sent.append(n)

    received: list[int] = []
    async with anyio.create_task_group() as tg:
        tg.start_soon(producer, 3)
        await anyio.wait_all_tasks_blocked()
        tg.start_soon(producer, 4)
        await anyio.wait_all_tasks_blocked()
        assert sent == []  # both wait for room
        assert not channel.send_nowait(5)  # no overtaking the waiting producers
        async for item in channel:
            received.append(item)
            if len(received) == 4:
                break
    assert received == [1, 2, 3, 4] and sorted(sent) == [3, 4]
    channel.send_nowait(6)
    channel.close()
    assert [item async for item in channel] == [6]  # the queued item, then the end
    with pytest.raises(anyio.ClosedResourceError):
        channel.send_nowait(7)


async def test_a_cancelled_producer_gives_up_its_place(anyio_backend: object) -> None:
    channel: Channel[str] = Channel(1)
    channel.bind()
    channel.send_nowait("a")
    scope = anyio.CancelScope()

    async def cancelled_sender() -> None:
        with scope:
            await channel.send("x")

    async with anyio.create_task_group() as tg:
        tg.start_soon(channel.send, "b")
        await anyio.wait_all_tasks_blocked()
        tg.start_soon(cancelled_sender)
        await anyio.wait_all_tasks_blocked()
        scope.cancel()  # "x" gives up its place in the queue
        await anyio.wait_all_tasks_blocked()
        tg.start_soon(channel.send, "c")
        await anyio.wait_all_tasks_blocked()
        got = []
        async for item in channel:
            got.append(item)
            if len(got) == 3:
                break
    assert got == ["a", "b", "c"]


async def test_close_wakes_the_consumer_and_fails_waiting_producers(
    anyio_backend: object,
) -> None:
    channel: Channel[int] = Channel(1)
    channel.bind()
    channel.send_nowait(1)
    errors: list[BaseException] = []

    async def producer() -> None:
        try:
            await channel.send(2)
        except anyio.ClosedResourceError as exc:
            errors.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(producer)
        await anyio.wait_all_tasks_blocked()
        channel.close()
    assert len(errors) == 1
    assert [item async for item in channel] == [1]
