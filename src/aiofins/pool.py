"""A connection pool keyed by endpoint: share sessions among tasks, keep them healthy.

``pool.client(url)`` lends a :class:`~aiofins.client.Client` for the endpoint. Sessions are
shared by :attr:`Endpoint.key <aiofins.endpoint.Endpoint.key>`: host, port and every option
that changes what is addressed or how (``?node=7``, ``?dest=3.5.0``, ``?timeout=0.3`` each get
their own session, what ``connect()`` with that URL gives). One session
multiplexes any number of concurrent tasks, so the default is one session per endpoint
(``max_per_endpoint=1``); with more, each extra session is opened when all existing ones are
busy and gets its own FINS source node (SA1) — an Ethernet unit replies to the last UDP port it
saw for a node, so two sockets sharing SA1 would steal each other's replies. FINS/TCP PLCs
accept few connections (each holds one of the unit's node slots): keep ``max_per_endpoint``
within that.

A maintenance task checks idle sessions every ``health_interval`` seconds with CPU UNIT STATUS
READ (0601) and closes those that fail or stayed unused for ``idle_timeout`` seconds. An
endpoint whose connection failed is not retried until its backoff (doubling from
``backoff_min`` to ``backoff_max``) has passed; calls in the meantime fail fast with
:class:`~aiofins.ConnectionLost`. A borrower waits for a connection being made at most its
timeout (``pool.client(url, timeout=...)``, by default the endpoint's request timeout), then
gets :class:`~aiofins.FinsTimeout`; the connection attempt goes on for the next borrower.

Safe to open in a FastAPI lifespan::

    @asynccontextmanager
    async def lifespan(app):
        async with aiofins.Pool() as pool:
            app.state.plcs = pool
            yield
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Awaitable, Callable
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import anyio
from anyio.abc import TaskGroup

from .client import Client
from .connection import (
    DEFAULT_TIMEOUT,
    check_options,
    connect,
    default_addresses,
    request_timeout,
)
from .endpoint import Endpoint, parse_endpoint
from .protocol.errors import CommandError, ConnectionLost, FinsError, FinsTimeout
from .protocol.header import FinsAddress
from .session import SessionStats
from .transport.base import is_asyncio


def event_loop_clock() -> Callable[[], float]:
    """``anyio.current_time`` as a direct call: the running asyncio loop's ``time``.

    (The same clock; anyio looks up the backend on every call. Other backends keep anyio's.)
    """
    if is_asyncio():
        return asyncio.get_running_loop().time
    return anyio.current_time


def backend_sleep() -> Callable[[float], Awaitable[None]]:
    """``anyio.sleep`` as a direct call: ``asyncio.sleep`` under asyncio (what anyio calls
    after looking up the backend on every call). Other backends keep anyio's."""
    if is_asyncio():
        return asyncio.sleep
    return anyio.sleep


@dataclass(eq=False)
class _Entry:
    #: The endpoint's key (link and options: what it addresses and how).
    key: str
    #: Where its frames go (``udp://host:port``): sessions of several keys may share it.
    link: str
    url: str
    src: FinsAddress | None
    dest: FinsAddress | None = None
    client: Client | None = None
    error: BaseException | None = None
    #: ``error``'s traceback when it happened (each borrower is handed the error with it).
    error_tb: TracebackType | None = None
    users: int = 0
    last_used: float = 0.0
    ready: anyio.Event = field(default_factory=anyio.Event)
    closing: anyio.Event = field(default_factory=anyio.Event)
    done: anyio.Event = field(default_factory=anyio.Event)
    #: Cancels the connect while it is being made (the pool closes meanwhile).
    connecting: anyio.CancelScope = field(default_factory=anyio.CancelScope)


@dataclass
class EndpointStats:
    """An endpoint's counters, summed over its sessions (see ``SessionStats`` for each).

    The counters (``completed`` to ``health_failures``) only grow: those of a session the
    pool closed (idle, failed health check) stay counted. ``sessions``, ``in_use``,
    ``in_flight`` and the latencies describe the sessions open now. ``connect_failures``
    counts the pool's failed first connects and its sessions' failed reconnects alike.
    """

    sessions: int = 0
    in_use: int = 0
    in_flight: int = 0
    completed: int = 0
    timeouts: int = 0
    late_replies: int = 0
    retries: int = 0
    connects: int = 0
    connect_failures: int = 0
    disconnects: int = 0
    health_failures: int = 0
    latency_mean: float = 0.0
    latency_p99: float = 0.0


#: The session counters an endpoint sums (and keeps when a session closes).
_SUMMED = (
    "completed",
    "timeouts",
    "late_replies",
    "retries",
    "connects",
    "connect_failures",
    "disconnects",
)


def _add_counters(into: EndpointStats, stats: SessionStats) -> None:
    for name in _SUMMED:
        setattr(into, name, getattr(into, name) + getattr(stats, name))


def _users(entry: _Entry) -> int:
    return entry.users


class _Lease:
    """``async with pool.client(url) as client``: one use of an endpoint's client."""

    __slots__ = ("entry", "pool", "timeout", "url")

    def __init__(self, pool: Pool, url: str, timeout: float | None) -> None:
        self.pool = pool
        self.url = url
        self.timeout = timeout
        self.entry: _Entry | None = None

    def borrow_ready(self) -> Client | None:
        """The client at once if a ready session can be lent without waiting, else None
        (then :meth:`borrow` waits). A scan loop calls this and :meth:`release` directly:
        no coroutine for the usual case."""
        entry = self.pool._ready_entry(self.url)
        if entry is None:
            return None
        self.entry = entry
        return entry.client

    async def borrow(self) -> Client:
        """The client, once the endpoint's session is ready, where :meth:`borrow_ready` had
        none at once (:meth:`release` gives it back)."""
        entry = await self.pool._acquire(self.url, self.timeout)
        self.entry = entry
        assert entry.client is not None
        return entry.client

    def release(self) -> None:
        """Give the client back (nothing if none was borrowed)."""
        entry = self.entry
        if entry is not None:
            self.entry = None
            entry.users -= 1
            entry.last_used = self.pool._now()

    async def __aenter__(self) -> Client:
        return self.borrow_ready() or await self.borrow()

    async def __aexit__(self, *exc_info: object) -> None:
        self.release()


class Pool:
    """Clients keyed by endpoint URL; see the module docstring."""

    def __init__(
        self,
        *,
        max_per_endpoint: int = 1,
        idle_timeout: float = 300.0,
        health_interval: float = 30.0,
        backoff_min: float = 0.5,
        backoff_max: float = 30.0,
        **connect_options: Any,
    ) -> None:
        if max_per_endpoint < 1:
            raise CommandError("max_per_endpoint must be at least 1")
        check_options(connect_options)
        self.max_per_endpoint = max_per_endpoint
        self.idle_timeout = idle_timeout
        self.health_interval = health_interval
        self.backoff_min = backoff_min
        self.backoff_max = backoff_max
        self.connect_options = connect_options
        self._entries: dict[str, list[_Entry]] = {}
        #: The same lists as ``_entries``, by the URL text callers use (no parsing per call).
        self._by_url: dict[str, list[_Entry]] = {}
        self._failures: dict[str, tuple[float, float]] = {}  # key -> (retry_at, backoff)
        self._stats: dict[str, EndpointStats] = {}
        self._tg: TaskGroup | None = None
        self._closed = False
        self._lock = anyio.Lock()
        self._now = anyio.current_time

    async def __aenter__(self) -> Pool:
        self._now = event_loop_clock()
        self._tg = anyio.create_task_group()
        await self._tg.__aenter__()
        self._tg.start_soon(self._maintain)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        await self.aclose()
        assert self._tg is not None
        tg, self._tg = self._tg, None
        tg.cancel_scope.cancel()
        return await tg.__aexit__(exc_type, exc, tb)

    async def aclose(self) -> None:
        """Close every session (in-flight calls fail with ``ConnectionLost``; so do borrowers
        waiting for a connection still being made, which is abandoned)."""
        self._closed = True
        entries = [e for lst in self._entries.values() for e in lst]
        self._entries.clear()
        self._by_url.clear()
        for entry in entries:
            entry.closing.set()
            if entry.client is None:
                entry.connecting.cancel()
        with anyio.CancelScope(shield=True):
            for entry in entries:
                await entry.done.wait()

    # -- lending ------------------------------------------------------------------------

    def client(
        self, url: str, *, timeout: float | None = None
    ) -> AbstractAsyncContextManager[Client]:
        """Lend the client of ``url``'s endpoint for the ``async with`` block.

        Waiting for the endpoint's connection to be made takes at most ``timeout`` seconds
        (default: the endpoint's request timeout, ``timeout=`` of the pool or ``?timeout=``
        of the URL), then raises :class:`FinsTimeout`; the attempt itself goes on (bounded by
        the transport's connect timeout) and serves later borrowers.
        """
        return self._lease(url, timeout)

    def _lease(self, url: str, timeout: float | None = None) -> _Lease:
        """:meth:`client`'s lease, also for the poller's scans (which borrow without
        ``async with``: see :meth:`_Lease.borrow_ready`)."""
        if timeout is not None and not timeout > 0:  # math.inf: no bound but connect_timeout
            raise CommandError(f"timeout must be a positive number of seconds, got {timeout}")
        return _Lease(self, url, timeout)

    def stats(self, url: str | None = None) -> dict[str, EndpointStats]:
        """Per-endpoint counters (all endpoints, or the one of ``url``)."""
        keys = [parse_endpoint(url).key] if url else list(self._stats)
        out: dict[str, EndpointStats] = {}
        for key in keys:
            agg = dataclasses.replace(self._stats.get(key, EndpointStats()))
            for entry in self._entries.get(key, []):
                if entry.client is None:
                    continue
                s = entry.client.session.stats
                agg.sessions += 1
                agg.in_use += entry.users
                agg.in_flight += s.in_flight
                _add_counters(agg, s)
                agg.latency_mean = max(agg.latency_mean, s.latency_mean)
                agg.latency_p99 = max(agg.latency_p99, s.latency_p99)
            out[key] = agg
        return out

    def _ready_entry(self, url: str) -> _Entry | None:
        """The fast path of lending: a ready session with no reason to open another one."""
        entries = self._by_url.get(url)
        if not entries or self._tg is None:
            return None
        best = entries[0] if len(entries) == 1 else min(entries, key=_users)
        if (
            best.client is not None
            and not best.closing.is_set()
            and (best.users == 0 or len(entries) >= self.max_per_endpoint)
        ):
            best.users += 1
            return best
        return None

    async def _acquire(self, url: str, timeout: float | None = None) -> _Entry:
        """The slow path of lending (:meth:`_ready_entry` found no session to lend)."""
        if self._closed:
            raise ConnectionLost("the pool is closed")
        if self._tg is None:
            raise RuntimeError("use 'async with Pool() as pool' before borrowing clients")
        endpoint = parse_endpoint(url)
        key = endpoint.key
        async with self._lock:
            entries = [e for e in self._entries.get(key, []) if not e.closing.is_set()]
            ready = [e for e in entries if e.error is None]
            idle = min(ready, key=_users, default=None)
            most = 1 if endpoint.scheme == "serial" else self.max_per_endpoint
            if idle is None or (idle.users and len(entries) < most):
                now = anyio.current_time()
                retry_at, _ = self._failures.get(key, (0.0, 0.0))
                if now < retry_at and idle is None:
                    raise ConnectionLost(
                        f"{key}: last connection attempt failed; retrying in {retry_at - now:.1f} s"
                    )
                dest, src = await self._addresses_for(endpoint, extra=bool(entries))
                entry = _Entry(key, endpoint.link, url, src, dest)
                self._entries.setdefault(key, []).append(entry)
                self._by_url[url] = self._entries[key]
                self._stats.setdefault(key, EndpointStats())
                assert self._tg is not None
                self._tg.start_soon(self._serve, entry)
            else:
                entry = idle
            entry.users += 1
        if not entry.ready.is_set():
            if timeout is None:  # the request timeout the endpoint's sessions get
                default = float(self.connect_options.get("timeout", DEFAULT_TIMEOUT))
                timeout = request_timeout(endpoint, default)
            try:
                with anyio.move_on_after(timeout):
                    await entry.ready.wait()
            except BaseException:  # the borrower was cancelled: it no longer uses the entry
                entry.users -= 1
                raise
            if not entry.ready.is_set():  # the attempt goes on: a later borrower may use it
                entry.users -= 1
                raise FinsTimeout(
                    f"{key}: no connection within {timeout} s: a connection attempt is still "
                    "in progress (a later borrower uses it once it succeeds)"
                )
        if entry.error is not None:
            entry.users -= 1
            err = entry.error
            if isinstance(err, FinsError):
                # The one error object of the entry: raised as is, its traceback would grow
                # by every earlier borrower's frames.
                raise err.with_traceback(entry.error_tb)
            raise ConnectionLost(f"{key}: {err}") from err
        return entry

    def _on_link(self, link: str) -> list[_Entry]:
        """The sessions (of any key) open or being opened to ``link``."""
        return [
            e
            for lst in self._entries.values()
            for e in lst
            if e.link == link and not e.closing.is_set()
        ]

    async def _addresses_for(
        self, endpoint: Endpoint, *, extra: bool
    ) -> tuple[FinsAddress | None, FinsAddress | None]:
        """(dest, source) of a new session to ``endpoint``; ``None``: left to connect().

        An Ethernet unit replies to the last UDP port it saw for a source node, so every UDP
        session to one host:port (whatever its key) gets a source node of its own: the one
        connect() would use if no other session there uses it as source or destination,
        else a free one (254 down). A source the URL or the pool names is kept for a new
        key: if another session to the same host:port uses its node, the URL is refused
        (:class:`CommandError`). A serial line carries one session: another key for the
        same device is refused while it is open.
        """
        others = self._on_link(endpoint.link)
        if endpoint.scheme == "serial":
            if any(e.key != endpoint.key for e in others):
                raise CommandError(
                    f"{endpoint.key}: {endpoint.link} is open in this pool with other settings "
                    f"({others[0].key}); a serial line carries one session"
                )
            return None, None
        if endpoint.scheme != "udp":
            return None, None
        dest, src = await default_addresses(
            endpoint, self.connect_options.get("dest"), self.connect_options.get("src")
        )
        used = {e.src.node for e in others if e.src is not None}
        taken = used | {e.dest.node for e in others if e.dest is not None}
        named = self.connect_options.get("src") or endpoint.option("src")
        if named is not None and not extra:
            if src.node in used:
                raise CommandError(
                    f"{endpoint.key}: source node {src.node} is used by another session to "
                    f"{endpoint.link} in this pool; the PLC would send each one's replies to "
                    "the other. Name another src, or leave it out"
                )
            return dest, src
        if src.node not in taken:
            return dest, src
        avoid = taken | {dest.node}
        node = next((n for n in range(254, 0, -1) if n not in avoid), None)
        if node is None:
            raise CommandError(f"{endpoint.link}: no free FINS source node for another session")
        return dest, FinsAddress(src.network, node, src.unit)

    async def _serve(self, entry: _Entry) -> None:
        options = dict(self.connect_options)
        if entry.src is not None:
            options["src"] = entry.src
        try:
            with entry.connecting:  # cancelled only while the connection is being made
                async with connect(entry.url, **options) as client:
                    entry.client = client
                    entry.last_used = anyio.current_time()
                    self._failures.pop(entry.key, None)
                    entry.ready.set()
                    await entry.closing.wait()
            if entry.client is None:  # the pool closed while connecting
                entry.error = ConnectionLost(f"{entry.key}: the pool closed while connecting")
        except (OSError, FinsError) as exc:
            entry.error = exc
            entry.error_tb = exc.__traceback__
            self._stats[entry.key].connect_failures += 1
            _, backoff = self._failures.get(entry.key, (0.0, 0.0))
            backoff = min(self.backoff_max, max(self.backoff_min, backoff * 2))
            self._failures[entry.key] = (anyio.current_time() + backoff, backoff)
        finally:
            entry.closing.set()
            entry.ready.set()
            entry.done.set()
            lst = self._entries.get(entry.key)
            if lst and entry in lst:
                lst.remove(entry)
            if entry.client is not None:  # its counters stay with the endpoint
                _add_counters(self._stats[entry.key], entry.client.session.stats)

    # -- maintenance ----------------------------------------------------------------------

    async def _maintain(self) -> None:
        while True:
            await anyio.sleep(min(self.health_interval, self.idle_timeout))
            now = anyio.current_time()
            for entries in list(self._entries.values()):
                for entry in list(entries):
                    if entry.client is None or entry.users or entry.closing.is_set():
                        continue
                    if now - entry.last_used >= self.idle_timeout:
                        entry.closing.set()
                        continue
                    if now - entry.last_used >= self.health_interval:
                        await self._health_check(entry)

    async def _health_check(self, entry: _Entry) -> None:
        assert entry.client is not None
        try:
            await entry.client.cpu_unit_status_read(timeout=entry.client.session.timeout)
        except FinsError:
            self._stats[entry.key].health_failures += 1
            entry.closing.set()
        else:
            entry.last_used = anyio.current_time()
