"""aiofins: async Omron FINS client, protocol codec and virtual PLC."""

import logging
from importlib.metadata import PackageNotFoundError, version

from .client import Client, ClientState
from .connection import connect
from .hooks import (
    ConnectionStateChanged,
    EventHooks,
    RequestRetried,
    RequestSent,
    RequestTimedOut,
    ResponseReceived,
    ScanDone,
    SidSpaceChanged,
)
from .poller import Poller, PollerState, Quality, ScanState, Snapshot
from .pool import Pool, PoolFull
from .protocol.areas import MemoryAddress
from .protocol.arrays import array_to_words, words_to_array
from .protocol.endcodes import EndCode
from .protocol.errors import (
    AddressError,
    CircuitOpen,
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
from .tagfile import TagFileError, load_tags
from .transport.memory import MemoryTransport

# A library leaves logging to the application: without a handler of its own, the "aiofins"
# records would reach logging's last resort and print WARNINGs on stderr of a script that
# handles FinsTimeout itself. (The command line configures logging in aiofins/cli/logs.py.)
logging.getLogger("aiofins").addHandler(logging.NullHandler())

try:
    __version__ = version("aiofins")  #: The installed distribution's version (pyproject.toml).
except PackageNotFoundError:  # pragma: no cover - imported from a source tree, not installed
    __version__ = "0+unknown"

__all__ = [
    "AddressError",
    "CircuitOpen",
    "Client",
    "ClientState",
    "CommandError",
    "ConnectionLost",
    "ConnectionStateChanged",
    "DecodeError",
    "EndCode",
    "EndCodeError",
    "EventHooks",
    "FinsAddress",
    "FinsError",
    "FinsTimeout",
    "FrameError",
    "MemoryAddress",
    "MemoryTransport",
    "Poller",
    "PollerState",
    "Pool",
    "PoolFull",
    "Quality",
    "ReadOnlyError",
    "RelayError",
    "RequestRetried",
    "RequestSent",
    "RequestTimedOut",
    "ResponseReceived",
    "ScanDone",
    "ScanState",
    "SidSpaceChanged",
    "Snapshot",
    "TagFileError",
    "__version__",
    "array_to_words",
    "connect",
    "load_tags",
    "words_to_array",
]
