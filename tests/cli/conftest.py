"""A virtual PLC for command-line tests, served by an event loop in a thread of its own (the
command line runs its own event loop in the test's thread)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from anyio.from_thread import start_blocking_portal

from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.simulator.state import Mode


@pytest.fixture
def plc() -> VirtualPLC:
    """The virtual PLC behind :func:`url`, in RUN mode as a PLC at work is."""
    return VirtualPLC(mode=Mode.RUN)


@pytest.fixture
def url(plc: VirtualPLC) -> Iterator[str]:
    """``udp://127.0.0.1:PORT`` of ``plc``."""
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(run_simulator(plc, udp=("127.0.0.1", 0))) as sim,
    ):
        yield f"udp://127.0.0.1:{sim.udp_port}"
