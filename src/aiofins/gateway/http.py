"""A small HTTP endpoint for probes and Prometheus: ``/healthz``, ``/readyz``, ``/metrics``.

``/healthz`` answers 200 while the gateway runs (a liveness probe); ``/readyz`` answers 200
while the MQTT link is connected, else 503 (a readiness probe); ``/metrics`` serves the
Prometheus text format. One request per connection (HTTP/1.0 style), GET and HEAD only.

Bounded: at most ``max_connections`` connections are served at once (the others wait in
the kernel's listen queue, not accepted: they hold no descriptor of ours), each has
``idle_timeout`` seconds to send its request and again to take the answer (a client that
sends nothing, or reads nothing, is cut off; the time the gateway takes to make the answer
is not the client's), a request head has at most 8 kB. An accept that fails ("Too many open
files") is counted and logged, and accepting resumes after a short pause: never fatal.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable

import anyio
from anyio.abc import SocketAttribute, SocketListener, SocketStream, TaskGroup

log = logging.getLogger("aiofins.gateway")

#: A route: () → (status, content type, body), awaited (a long answer, such as ``/metrics``,
#: is made in steps that let the event loop run).
Handler = Callable[[], Awaitable[tuple[int, str, bytes]]]

_REASONS = {
    200: "OK",
    400: "Bad Request",
    404: "Not Found",
    405: "Method Not Allowed",
    503: "Service Unavailable",
}
_MAX_REQUEST = 8192
#: Connections served at once, and seconds each may take, by default.
MAX_CONNECTIONS = 64
IDLE_TIMEOUT = 5.0
#: Seconds to wait after a failed accept before the next (descriptors may be freed by then).
ACCEPT_PAUSE = 0.1


class HttpServer:
    """Serves ``routes`` on ``host:port`` (port 0: a free one, see :attr:`port`)."""

    def __init__(
        self,
        host: str,
        port: int,
        routes: dict[str, Handler],
        *,
        max_connections: int = MAX_CONNECTIONS,
        idle_timeout: float = IDLE_TIMEOUT,
    ) -> None:
        self.host = host
        self.port = port
        self.routes = routes
        self.max_connections = max_connections
        self.idle_timeout = idle_timeout
        self.requests = 0
        #: Connections being served now.
        self.connections = 0
        #: Accepts that failed (descriptors exhausted, ...), and connections cut off idle.
        self.accept_errors = 0
        self.timeouts = 0
        self._slots = anyio.Semaphore(max_connections)

    async def serve(
        self, *, task_status: anyio.abc.TaskStatus[int] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        listeners = await anyio.create_tcp_listener(local_host=self.host, local_port=self.port)
        async with listeners, anyio.create_task_group() as tg:
            self.port = int(listeners.extra(SocketAttribute.local_port))
            task_status.started(self.port)
            for listener in listeners.listeners:
                tg.start_soon(self._accept, listener, tg)

    async def _accept(self, listener: anyio.abc.Listener[SocketStream], tg: TaskGroup) -> None:
        """Accept while a slot is free: a flood waits in the listen queue, not in memory."""
        assert isinstance(listener, SocketListener)
        while True:
            await self._slots.acquire()
            try:
                stream = await listener.accept()
            except OSError as exc:  # EMFILE, ENFILE, ENOBUFS, ...: counted, never fatal
                self._slots.release()
                self.accept_errors += 1
                if self.accept_errors == 1 or self.accept_errors % 100 == 0:
                    log.error(
                        "HTTP accept failed (%d so far): %s; serving on", self.accept_errors, exc
                    )
                await anyio.sleep(ACCEPT_PAUSE)
                continue
            except BaseException:
                self._slots.release()
                raise
            self.connections += 1
            tg.start_soon(self._serve_one, stream)

    async def _serve_one(self, stream: SocketStream) -> None:
        try:
            await self._handle(stream)
        finally:
            self.connections -= 1
            self._slots.release()

    async def _handle(self, stream: SocketStream) -> None:
        async with stream:
            try:
                with anyio.fail_after(self.idle_timeout):
                    request = await self._read_head(stream)
                status, ctype, body, head_only = await self._respond(request)
                header = (
                    f"HTTP/1.1 {status} {_REASONS.get(status, '')}\r\n"
                    f"Content-Type: {ctype}\r\nContent-Length: {len(body)}\r\n"
                    "Connection: close\r\n\r\n"
                ).encode("ascii")
                with anyio.fail_after(self.idle_timeout):
                    await stream.send(header if head_only else header + body)
            except TimeoutError:
                self.timeouts += 1
            except (OSError, anyio.BrokenResourceError, anyio.EndOfStream):
                pass  # a client that went away or never finished its request

    async def _read_head(self, stream: SocketStream) -> bytes:
        data = b""
        while b"\r\n\r\n" not in data and b"\n\n" not in data and len(data) < _MAX_REQUEST:
            data += await stream.receive()
        return data

    async def _respond(self, request: bytes) -> tuple[int, str, bytes, bool]:
        self.requests += 1
        line = request.split(b"\n", 1)[0].decode("latin-1").strip().split()
        if len(line) != 3:
            return 400, "text/plain", b"bad request\n", False
        method, target, _ = line
        if method not in ("GET", "HEAD"):
            return 405, "text/plain", b"GET or HEAD only\n", False
        handler = self.routes.get(target.split("?", 1)[0])
        if handler is None:
            return 404, "text/plain", b"not found\n", method == "HEAD"
        try:
            status, ctype, body = await handler()
        except Exception:  # a broken handler answers 500 and the server goes on
            log.exception("HTTP handler for %s failed", target)
            return 500, "text/plain", b"internal error\n", False
        return status, ctype, body, method == "HEAD"
