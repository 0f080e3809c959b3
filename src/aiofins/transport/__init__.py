"""Transports: move whole FINS frames over UDP, FINS/TCP or a Host Link serial line."""

from __future__ import annotations

from .base import FrameSink, Transport
from .serial import SerialTransport
from .tcp import TcpTransport
from .udp import UdpTransport

__all__ = ["FrameSink", "SerialTransport", "TcpTransport", "Transport", "UdpTransport"]
