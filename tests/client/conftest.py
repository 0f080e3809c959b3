"""A virtual PLC served on loopback UDP and TCP for the client tests."""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest

from aiofins.simulator.faults import FaultPlan
from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import Simulator, run_simulator


@pytest.fixture
async def sim(anyio_backend: object) -> AsyncIterator[Simulator]:
    async with run_simulator(
        VirtualPLC(), udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0), faults=FaultPlan(seed=1)
    ) as running:
        yield running


@pytest.fixture(params=["udp", "tcp"])
def scheme(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def url(sim: Simulator, scheme: str) -> str:
    port = sim.udp_port if scheme == "udp" else sim.tcp_port
    return f"{scheme}://127.0.0.1:{port}"
