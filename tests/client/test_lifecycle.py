"""What connect() returns opens and closes with ``async with`` or explicitly
(``await plc.open()`` ... ``await plc.aclose()``), and says so when used outside its life."""

from __future__ import annotations

import socket

import anyio
import pytest

from aiofins import Client, ClientState, CommandError, ConnectionLost, Pool, connect
from aiofins.simulator.runner import Simulator

pytestmark = pytest.mark.anyio


def state(plc: Client) -> ClientState:
    """``plc.state`` as it is now (mypy would keep an earlier assert's narrowing)."""
    return plc.state


async def test_open_use_and_close_explicitly(sim: Simulator) -> None:
    plc = connect(f"udp://127.0.0.1:{sim.udp_port}", timeout=2)
    assert state(plc) is ClientState.NEW
    with pytest.raises(ConnectionLost, match=r"is not open: await plc\.open\(\) first"):
        await plc.read("D0")
    assert await plc.open() is plc
    assert state(plc) is ClientState.OPEN
    await plc.write("D0", [7])
    assert await plc.read("D0") == [7]
    await plc.aclose()
    assert state(plc) is ClientState.CLOSED
    with pytest.raises(ConnectionLost, match=r"is closed: aiofins\.connect\(url\) makes a new"):
        await plc.read("D0")
    await plc.aclose()  # again: nothing
    with pytest.raises(CommandError, match=r"is closed: aiofins\.connect"):
        await plc.open()


async def test_clients_close_in_any_order_from_any_task(sim: Simulator) -> None:
    """Each session runs in a task of its own: closing the first opened first (not nested as
    ``async with`` blocks are), or from another task, is fine."""
    url = f"udp://127.0.0.1:{sim.udp_port}"
    first, second = connect(url), connect(f"tcp://127.0.0.1:{sim.tcp_port}")
    await first.open()
    await second.open()
    assert await first.read("D0") == await second.read("D0")
    await first.aclose()
    assert await second.read("D0") == [0]
    async with anyio.create_task_group() as tg:
        tg.start_soon(second.aclose)
    assert (state(first), state(second)) == (ClientState.CLOSED, ClientState.CLOSED)


async def test_a_call_waiting_when_the_client_closes_ends_with_connection_lost(
    anyio_backend: object,
) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        plc = connect(f"udp://127.0.0.1:{silent.getsockname()[1]}", timeout=30)
        await plc.open()
        failures: list[BaseException] = []

        async def read() -> None:
            try:
                await plc.read("D0")
            except ConnectionLost as exc:
                failures.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            await anyio.wait_all_tasks_blocked()
            await plc.aclose()
        assert len(failures) == 1


async def test_an_error_opening_is_raised_by_open(anyio_backend: object) -> None:
    plc = connect("udp://127.0.0.1?read_only=0&read_only=1")
    with pytest.raises(CommandError, match="given twice"):
        await plc.open()
    assert state(plc) is ClientState.CLOSED
    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))  # bound, not listening: the connect is refused
        plc = connect(f"tcp://127.0.0.1:{closed.getsockname()[1]}", timeout=0.5)
        with pytest.raises(ConnectionLost):
            await plc.open()
    assert state(plc) is ClientState.CLOSED
    with pytest.raises(ConnectionLost, match="is closed"):
        await plc.read("D0")


async def test_async_with_still_works_and_aclose_inside_it(sim: Simulator) -> None:
    url = f"udp://127.0.0.1:{sim.udp_port}"
    async with connect(url) as plc:
        assert state(plc) is ClientState.OPEN
        with pytest.raises(CommandError, match="is open already"):
            await plc.open()
        await plc.aclose()
        assert state(plc) is ClientState.CLOSED
    assert state(plc) is ClientState.CLOSED
    with pytest.raises(ZeroDivisionError):  # the block's exception passes unchanged
        async with connect(url) as plc:
            raise ZeroDivisionError
    assert state(plc) is ClientState.CLOSED


async def test_a_pool_lease_stays_async_with(sim: Simulator) -> None:
    async with Pool() as pool, pool.client(f"udp://127.0.0.1:{sim.udp_port}") as plc:
        assert state(plc) is ClientState.OPEN
        with pytest.raises(CommandError, match="a Pool's lease"):
            await plc.aclose()
        with pytest.raises(CommandError, match="a Pool's lease"):
            await plc.open()
        assert await plc.read("D0") == [0]


async def test_a_client_never_opened_holds_nothing(anyio_backend: object) -> None:
    plc = connect("udp://127.0.0.1:9")
    await plc.aclose()
    assert state(plc) is ClientState.CLOSED
