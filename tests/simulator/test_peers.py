"""Independent FINS clients read and write the virtual PLC (optional: skipped without them).

The PyPI package ``fins`` (``pip install fins``) is a blocking client written by others; it
talks to the simulator from this thread while the simulator runs in a portal thread.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from anyio.from_thread import start_blocking_portal

from aiofins.simulator.plc import VirtualPLC
from aiofins.simulator.runner import run_simulator


@pytest.fixture
def sim_port() -> Iterator[tuple[VirtualPLC, int]]:
    plc = VirtualPLC()
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(run_simulator(plc, udp=("127.0.0.1", 0))) as sim,
    ):
        yield plc, sim.udp_port


def test_pypi_fins_reads_and_writes_dm(sim_port: tuple[VirtualPLC, int]) -> None:
    udp = pytest.importorskip("fins.udp", reason="optional peer: pip install fins")
    plc, port = sim_port
    client = udp.UDPFinsConnection()
    client.connect("127.0.0.1", port=port, bind_port=0)
    client.dest_node_add = 1
    client.srce_node_add = 25
    try:
        response = client.memory_area_write(b"\x82", b"\x00\x64\x00", b"\x12\x34\xab\xcd", 2)
        assert response[10:14] == b"\x01\x02\x00\x00"  # 0102, normal completion
        response = client.memory_area_read(b"\x82", b"\x00\x64\x00", 2)
        assert response[10:14] == b"\x01\x01\x00\x00"
        assert response[14:] == b"\x12\x34\xab\xcd"
        assert response[3:6] == bytes((0, 25, 0))  # answered to the peer's source node
        status = client.cpu_unit_status_read()
        assert status[10:14] == b"\x06\x01\x00\x00"
        assert plc.frames_handled == 3
    finally:
        client.fins_socket.close()
