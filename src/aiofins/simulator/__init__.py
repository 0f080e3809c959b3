"""The virtual PLC and its servers (FINS/UDP, FINS/TCP, Host Link serial) with fault injection.

Built on :mod:`aiofins.protocol` only, never on the client, so a bug in one cannot hide a bug
in the other. Quick start::

    from aiofins.simulator import VirtualPLC, run_simulator

    async with run_simulator(VirtualPLC(node=1), udp=("127.0.0.1", 0)) as sim:
        print(sim.udp_port)
"""

from __future__ import annotations

from .ethernet import AddressConversion, EthernetUnit
from .faults import (
    BUSY_END_CODE,
    Delay,
    Dispatcher,
    FaultCounters,
    FaultDecision,
    FaultPlan,
    FaultRule,
    FrameHandler,
    FrameLog,
)
from .plc import VirtualPLC
from .runner import Simulator, run_simulator
from .serial import SerialServer, SerialSettings
from .state import Mode
from .tcp import TcpServer
from .udp import UdpServer

__all__ = [
    "BUSY_END_CODE",
    "AddressConversion",
    "Delay",
    "Dispatcher",
    "EthernetUnit",
    "FaultCounters",
    "FaultDecision",
    "FaultPlan",
    "FaultRule",
    "FrameHandler",
    "FrameLog",
    "Mode",
    "SerialServer",
    "SerialSettings",
    "Simulator",
    "TcpServer",
    "UdpServer",
    "VirtualPLC",
    "run_simulator",
]
