"""Transports: move whole FINS frames over UDP, FINS/TCP, a Host Link serial line, or in memory."""

from __future__ import annotations

from .base import FrameSink, Transport
from .memory import FrameHandler, MemoryTransport
from .serial import SerialTransport
from .tcp import TcpTransport
from .udp import UdpTransport

__all__ = [
    "FrameHandler",
    "FrameSink",
    "MemoryTransport",
    "SerialTransport",
    "TcpTransport",
    "Transport",
    "UdpTransport",
]
