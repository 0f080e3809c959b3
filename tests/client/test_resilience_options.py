"""The circuit breaker's and the reconnection's settings on connect(), URLs and Pool."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from typing import Any

import pytest

from aiofins import CircuitOpen, CommandError, FinsTimeout, Pool, connect

pytestmark = pytest.mark.anyio


@pytest.fixture
def silent_url() -> Iterator[str]:
    """A UDP port that takes every request and answers none: a PLC switched off."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:
        silent.bind(("127.0.0.1", 0))
        yield f"udp://127.0.0.1:{silent.getsockname()[1]}"


@pytest.mark.parametrize("where", ["keyword", "url"])
async def test_breaker_threshold_and_cooldown_on_connect(
    anyio_backend: object, silent_url: str, where: str
) -> None:
    """``connect(url, breaker_threshold=1)`` was refused as an unknown option: the breaker
    could be neither tuned nor turned off. One call without an answer opens it now, and
    with a 30 s cooldown the next call fails at once, nothing sent."""
    if where == "keyword":
        opened = connect(
            silent_url, timeout=0.1, retries=0, breaker_threshold=1, breaker_cooldown=(30, 60)
        )
    else:
        url = f"{silent_url}?timeout=0.1&breaker_threshold=1&breaker_cooldown=30,60"
        opened = connect(url, retries=0)
    async with opened as plc:
        assert plc.session._breaker.cooldown == (30.0, 60.0)
        with pytest.raises(FinsTimeout):
            await plc.read("D0")
        with pytest.raises(CircuitOpen):
            await plc.read("D0")
        assert plc.session.stats.breaker_rejects == 1


async def test_breaker_threshold_zero_never_opens(anyio_backend: object, silent_url: str) -> None:
    async with connect(silent_url, timeout=0.05, retries=0, breaker_threshold=0) as plc:
        for _ in range(7):  # more than the default threshold, 5
            with pytest.raises(FinsTimeout):
                await plc.read("D0")


async def test_reconnect_backoff_from_keyword_and_url(anyio_backend: object) -> None:
    from aiofins.simulator import VirtualPLC, run_simulator

    async with run_simulator(VirtualPLC(), tcp=("127.0.0.1", 0)) as sim:
        url = f"tcp://127.0.0.1:{sim.tcp_port}"
        async with connect(f"{url}?reconnect_backoff=0.5,30") as plc:
            assert plc.session.reconnect_backoff == (0.5, 30.0)
        async with connect(f"{url}?reconnect_backoff=0.5,30", reconnect_backoff=(1, 2)) as plc:
            assert plc.session.reconnect_backoff == (1.0, 2.0)  # the keyword wins
        async with connect(url) as plc:
            assert plc.session.reconnect_backoff == (0.05, 5.0)  # the session's default


async def test_a_pool_passes_them_to_every_session_and_the_url_wins(
    anyio_backend: object, silent_url: str
) -> None:
    async with Pool(timeout=0.1, breaker_threshold=1, breaker_cooldown=(30, 60)) as pool:
        async with pool.client(silent_url) as plc:
            with pytest.raises(FinsTimeout):
                await plc.read("D0", retries=0)
            with pytest.raises(CircuitOpen):
                await plc.read("D0", retries=0)
        async with pool.client(f"{silent_url}?breaker_threshold=0") as plc:
            for _ in range(3):
                with pytest.raises(FinsTimeout):
                    await plc.read("D0", retries=0)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"breaker_threshold": -1}, "breaker_threshold must be a whole number, at least 0"),
        ({"breaker_threshold": "2"}, "breaker_threshold must be a whole number"),
        ({"breaker_cooldown": 2}, r"breaker_cooldown must be a pair \(min, max\) of seconds"),
        ({"breaker_cooldown": (3, 1)}, "breaker_cooldown must be MIN,MAX seconds"),
        ({"reconnect_backoff": "0.1,2"}, "reconnect_backoff must be a pair"),
    ],
)
async def test_bad_settings_are_refused_before_anything_opens(
    anyio_backend: object, options: dict[str, Any], message: str
) -> None:
    with pytest.raises(CommandError, match=message):
        async with connect("udp://127.0.0.1:1", **options):
            pass  # pragma: no cover
    with pytest.raises(CommandError, match=message):
        Pool(**options)
