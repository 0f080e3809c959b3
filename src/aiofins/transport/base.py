"""The transport contract: move whole FINS frames over one medium, know nothing about SIDs.

A transport is opened with a :class:`FrameSink` (the session). It *pushes* every complete
FINS frame it receives to ``sink.frame_received(frame)`` and reports framing faults and the
end of the connection through the other two sink methods. Pushing (instead of a receive loop
in the session) lets the asyncio transports hand a datagram to its waiting request straight
from the event loop's callback: one wake-up per request instead of two.

A transport may need a background reader (trio, or any stream read through anyio); it starts
it with the spawner (task group) the session gives to :meth:`Transport.open`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Sized
from typing import Any, Protocol

from ..protocol.errors import FinsError
from ..protocol.header import FinsAddress


class FrameSink(Protocol):
    """What a transport reports to (implemented by the session).

    A sink may also have ``replies_awaited``: a sized collection, empty while no request
    awaits a reply. A datagram transport then stops draining its socket after the last
    awaited reply instead of paying one more ``recv()`` that fails (a stray datagram is read
    at the next readiness callback: the readiness is level-triggered).
    """

    def frame_received(self, frame: bytes, _addr: object = None, /) -> None:
        """One whole FINS frame (10-byte header first) arrived."""

    def frame_dropped(self, reason: str) -> None:
        """Bytes arrived that do not form a usable frame (bad FCS, bad envelope, ...)."""

    def connection_lost(self, exc: BaseException | None) -> None:
        """The link is gone (``exc`` is ``None`` after a local close)."""


class TaskSpawner(Protocol):
    """Where a transport starts its background reader (an anyio task group will do)."""

    def start_soon(self, func: Callable[..., Awaitable[Any]], *args: Any) -> None: ...


class Transport(ABC):
    """Moves FINS frames. Subclasses: UDP, FINS/TCP, Host Link serial."""

    #: Requests the medium can carry at once (``None`` = no limit of its own).
    max_in_flight: int | None = None
    #: Our FINS node as assigned by the peer (FINS/TCP handshake), else ``None``.
    local_node: int | None = None
    #: The peer's FINS node as told by the peer (FINS/TCP handshake), else ``None``.
    remote_node: int | None = None
    #: Whether the transport can be opened again after the link was lost.
    reconnectable: bool = False
    #: Whether each :meth:`open` starts a link no reply to an earlier one can reach (a new
    #: FINS/TCP connection): the session then forgets its quarantined and lingering SIDs.
    fresh_sid_space: bool = False
    #: Whether each socket of this medium needs a FINS source node (SA1) of its own: a UDP
    #: peer replies to the last port it saw for a node, so two sockets sharing SA1 steal each
    #: other's replies. (A FINS/TCP connection gets its node from its handshake.)
    own_source_node: bool = False
    #: SID spaces (sockets or connections to the peer, see :meth:`another`) a session opens
    #: at most by default: 1 where the medium has a single link.
    default_sid_spaces: int = 1
    #: Whether the medium delivers every frame it accepts, in order, or fails the link (a
    #: stream: FINS/TCP, in memory): the session then never retransmits after its adaptive
    #: retransmission timeout, only on the call's own schedule (see docs/session.md).
    reliable: bool = False
    #: A synchronous send the session may call instead of ``await send()`` (set while open
    #: by transports that never need to wait, e.g. asyncio UDP); ``None`` otherwise.
    fast_send: Callable[[bytes], None] | None = None
    #: Like :attr:`fast_send` for several frames at once, in order (FINS/TCP writes them with
    #: one system call); set together with ``fast_send``, ``None`` otherwise.
    fast_send_many: Callable[[list[bytes]], None] | None = None
    #: A synchronous "hand over what has already arrived, without waiting" the session may
    #: call right after a send (set while open by transports that can read their socket
    #: directly under asyncio); ``None`` otherwise. On one shared core the peer often answers
    #: during the send itself, and the request then completes without an event-loop pass.
    poll_now: Callable[[], None] | None = None

    @property
    @abstractmethod
    def is_open(self) -> bool:
        """True while frames can be sent."""

    @property
    @abstractmethod
    def description(self) -> str:
        """Where the frames go, for error messages (e.g. ``udp://10.0.0.1:9600``)."""

    @abstractmethod
    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        """Open (or re-open) the link; raise :class:`ConnectionLost`/``OSError`` on failure."""

    @abstractmethod
    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        """Send one whole FINS frame; raise :class:`ConnectionLost` if the link is gone, and
        :class:`FinsTimeout` if the frame cannot be written within ``timeout`` seconds (a
        stream whose peer stopped reading; the link is then ended if part of it went out)."""

    @abstractmethod
    async def aclose(self) -> None:
        """Close the link and release the socket (idempotent)."""

    def another(self) -> Transport | None:
        """A new, closed transport to the same peer with a socket or connection of its own:
        another SID space, which nothing sent through this one can reach (a session opens
        one when all 256 SIDs of this one are taken). ``None`` where the medium has a single
        link (a serial line)."""
        return None

    def silence_advice(self, dest: FinsAddress, source: FinsAddress) -> str:
        """What to check when a request to ``dest`` from ``source`` got no reply at all (the
        end of a :class:`~aiofins.FinsTimeout`'s message): FINS addressing over a network."""
        return (
            f"Check the destination node (DA1={dest.node}) and unit (DA2={dest.unit}) match "
            f"the PLC, that our source node (SA1={source.node}) is not used by another client "
            "and is allowed by the PLC's node settings, the port, and that the PLC is reachable"
        )


#: What :func:`replies_awaited` answers for a sink without ``replies_awaited``: never empty.
_ALWAYS: Sized = (None,)


def replies_awaited(sink: FrameSink) -> Sized:
    """The sink's ``replies_awaited`` collection, or one that is never empty."""
    awaited: Sized = getattr(sink, "replies_awaited", _ALWAYS)
    return awaited


def url_host(host: str) -> str:
    """``host`` as a URL writes it: an IPv6 address in brackets (``[::1]``)."""
    return f"[{host}]" if ":" in host else host


def is_uvloop(loop: object) -> bool:
    """Whether ``loop`` is uvloop's (its transports are not asyncio's subclasses)."""
    return type(loop).__module__.startswith("uvloop")


def is_asyncio() -> bool:
    """True when running under asyncio (stock or uvloop): the callback fast path applies.

    (anyio no longer depends on sniffio, so ask asyncio itself: under trio there is no
    running asyncio loop.)
    """
    import asyncio

    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return False
    return True


def wrap_os_error(exc: BaseException, where: str) -> FinsError:
    """A :class:`ConnectionLost` naming the endpoint, for errors raised by the socket layer."""
    from ..protocol.errors import ConnectionLost

    if isinstance(exc, FinsError):
        return exc
    err = ConnectionLost(f"{where}: {exc or type(exc).__name__}")
    err.__cause__ = exc
    return err
