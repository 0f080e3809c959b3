"""A small HTTP endpoint for probes and Prometheus: ``/healthz``, ``/readyz``, ``/metrics``.

``/healthz`` answers 200 while the gateway runs (a liveness probe); ``/readyz`` answers 200
while the MQTT link is connected, else 503 (a readiness probe); ``/metrics`` serves the
Prometheus text format. One request per connection (HTTP/1.0 style), GET and HEAD only.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import anyio
from anyio.abc import SocketAttribute, SocketStream

log = logging.getLogger("aiofins.gateway")

#: A route: () → (status, content type, body).
Handler = Callable[[], tuple[int, str, bytes]]

_REASONS = {
    200: "OK",
    400: "Bad Request",
    404: "Not Found",
    405: "Method Not Allowed",
    503: "Service Unavailable",
}
_MAX_REQUEST = 8192
_READ_TIMEOUT = 5.0


class HttpServer:
    """Serves ``routes`` on ``host:port`` (port 0: a free one, see :attr:`port`)."""

    def __init__(self, host: str, port: int, routes: dict[str, Handler]) -> None:
        self.host = host
        self.port = port
        self.routes = routes
        self.requests = 0

    async def serve(
        self, *, task_status: anyio.abc.TaskStatus[int] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        listener = await anyio.create_tcp_listener(local_host=self.host, local_port=self.port)
        async with listener:
            self.port = int(listener.extra(SocketAttribute.local_port))
            task_status.started(self.port)
            await listener.serve(self._handle)

    async def _handle(self, stream: SocketStream) -> None:
        async with stream:
            try:
                with anyio.fail_after(_READ_TIMEOUT):
                    request = await self._read_head(stream)
                status, ctype, body, head_only = self._respond(request)
                header = (
                    f"HTTP/1.1 {status} {_REASONS.get(status, '')}\r\n"
                    f"Content-Type: {ctype}\r\nContent-Length: {len(body)}\r\n"
                    "Connection: close\r\n\r\n"
                ).encode("ascii")
                await stream.send(header if head_only else header + body)
            except (TimeoutError, OSError, anyio.BrokenResourceError, anyio.EndOfStream):
                pass  # a client that went away or never finished its request

    async def _read_head(self, stream: SocketStream) -> bytes:
        data = b""
        while b"\r\n\r\n" not in data and b"\n\n" not in data and len(data) < _MAX_REQUEST:
            data += await stream.receive()
        return data

    def _respond(self, request: bytes) -> tuple[int, str, bytes, bool]:
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
            status, ctype, body = handler()
        except Exception:  # a broken handler answers 500 and the server goes on
            log.exception("HTTP handler for %s failed", target)
            return 500, "text/plain", b"internal error\n", False
        return status, ctype, body, method == "HEAD"
