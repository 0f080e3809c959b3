"""aiofins: async Omron FINS client, protocol codec and virtual PLC."""

from .client import Client
from .connection import connect
from .poller import Poller, Quality, Snapshot
from .pool import Pool, PoolFull
from .protocol.areas import MemoryAddress
from .protocol.endcodes import EndCode
from .protocol.errors import (
    AddressError,
    CommandError,
    ConnectionLost,
    DecodeError,
    EndCodeError,
    FinsError,
    FinsTimeout,
    FrameError,
    ReadOnlyError,
    RelayError,
)
from .protocol.header import FinsAddress

__version__ = "0.1.0"

__all__ = [
    "AddressError",
    "Client",
    "CommandError",
    "ConnectionLost",
    "DecodeError",
    "EndCode",
    "EndCodeError",
    "FinsAddress",
    "FinsError",
    "FinsTimeout",
    "FrameError",
    "MemoryAddress",
    "Poller",
    "Pool",
    "PoolFull",
    "Quality",
    "ReadOnlyError",
    "RelayError",
    "Snapshot",
    "__version__",
    "connect",
]
