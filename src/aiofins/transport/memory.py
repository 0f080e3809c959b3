"""An in-memory transport: frames go to a function in this process, no socket at all.

``MemoryTransport(handler)`` hands every FINS command frame the session sends to
``handler(frame)`` and the bytes it returns (a response frame, or ``None`` for no answer) back
to the session as if they had come from the network. With the simulator's
:meth:`VirtualPLC.handle_frame <aiofins.simulator.VirtualPLC.handle_frame>` as the handler a
test talks to a complete virtual PLC (memory, modes, end codes) through the real session and
client, without a socket::

    plc = VirtualPLC()
    async with aiofins.connect(transport=MemoryTransport(plc.handle_frame)) as client:
        await client.write("D0", [1, 2, 3])

Any callable with that shape will do (a hand-written fake answering only what a test needs),
so this module does not import the simulator (the client and the simulator share only
``protocol/``).

A reply is never handed over inside the send: it is queued, then delivered by the session's
read-after-send (``poll_now``) or, at the latest, by the transport's reader task at the next
event-loop pass, as a reply from a socket would be. Sending and receiving thus interleave
as they do on a network, and many requests in flight cannot recurse into one another.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import anyio

from ..protocol.errors import ConnectionLost
from .base import FrameSink, TaskSpawner, Transport

#: Answers one FINS command frame: the response frame, or ``None`` (no response).
FrameHandler = Callable[[bytes], bytes | None]


class MemoryTransport(Transport):
    """FINS frames to ``handler`` in this process (see the module's docstring).

    ``name`` is what :attr:`description` (and so error messages) call the endpoint. Every
    frame the handler answered and every reply delivered are counted (:attr:`frames_sent`,
    :attr:`replies`), for tests that check how often the "PLC" was asked.
    """

    reconnectable = True
    reliable = True

    def __init__(self, handler: FrameHandler, *, name: str = "memory") -> None:
        self.handler = handler
        self.name = name
        #: Frames handed to the handler, and replies handed to the session.
        self.frames_sent = 0
        self.replies = 0
        self._sink: FrameSink | None = None
        self._queued: deque[bytes] = deque()
        self._wake: anyio.Event | None = None

    @property
    def is_open(self) -> bool:
        return self._sink is not None

    @property
    def description(self) -> str:
        return f"memory://{self.name}"

    def another(self) -> MemoryTransport:
        """Another transport to the same handler (another SID space, for tests of them)."""
        return MemoryTransport(self.handler, name=self.name)

    async def open(self, sink: FrameSink, task_group: TaskSpawner) -> None:
        if self._sink is not None:
            return
        self._sink = sink
        self._queued.clear()
        self._wake = anyio.Event()
        self.fast_send = self._send_now
        self.poll_now = self._deliver
        task_group.start_soon(self._reader, sink)

    def _send_now(self, frame: bytes) -> None:
        """Hand ``frame`` to the handler; queue its reply (delivered after the send)."""
        if self._sink is None:
            raise ConnectionLost(f"{self.description} is closed")
        self.frames_sent += 1
        reply = self.handler(frame)
        if reply is not None:
            self._queued.append(bytes(reply))
            wake = self._wake
            if wake is not None:
                wake.set()

    def _deliver(self) -> None:
        """Hand every queued reply to the session, in order."""
        sink, queued = self._sink, self._queued
        while queued and sink is self._sink and sink is not None:
            self.replies += 1
            sink.frame_received(queued.popleft())

    async def _reader(self, sink: FrameSink) -> None:
        """Deliver what was queued and not read right after its send (requests in flight
        together), one event-loop pass after it was queued."""
        while self._sink is sink:
            wake = self._wake
            if wake is None:
                return
            await wake.wait()
            if self._sink is not sink:
                return
            self._wake = anyio.Event()
            self._deliver()

    async def send(self, frame: bytes, timeout: float | None = None) -> None:
        self._send_now(frame)

    def lose_connection(self, exc: BaseException | None = None) -> None:
        """End the link as a network failure would (for tests of what a session does then):
        replies not yet delivered are lost, the session is told (``exc``, by default a
        :class:`ConnectionLost`) and may open the transport again."""
        sink = self._sink
        if sink is None:
            return
        self._close()
        sink.connection_lost(exc or ConnectionLost(f"{self.description}: the link was lost"))

    def _close(self) -> None:
        self._sink = None
        self.fast_send = None
        self.poll_now = None
        self._queued.clear()
        wake, self._wake = self._wake, None
        if wake is not None:
            wake.set()  # the reader sees the transport closed and ends

    async def aclose(self) -> None:
        self._close()
