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
from .plant import Network, Plant, RoutingTables, Station, StationState, Unit
from .plantfile import load_plant
from .plantserver import PlantServer, serve_plant
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
    "Network",
    "Plant",
    "PlantServer",
    "RoutingTables",
    "SerialServer",
    "SerialSettings",
    "Simulator",
    "Station",
    "StationState",
    "TcpServer",
    "UdpServer",
    "Unit",
    "VirtualPLC",
    "load_plant",
    "run_simulator",
    "serve_plant",
]
