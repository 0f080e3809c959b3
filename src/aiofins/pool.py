"""A connection pool keyed by endpoint: share sessions among tasks, keep them healthy.

``pool.client(url)`` lends a :class:`~aiofins.client.Client` for the endpoint. Sessions are
shared by :attr:`Endpoint.key <aiofins.endpoint.Endpoint.key>`: host, port and every option
that changes what is addressed or how (``?node=7``, ``?dest=3.5.0``, ``?timeout=0.3`` each get
their own session, what ``connect()`` with that URL gives). One session multiplexes any number
of concurrent tasks, so the default is one session per endpoint (``max_per_endpoint=1``); with
more, each extra session is opened when all existing ones are busy. Every UDP session to one
host:port gets its own FINS source node (SA1) — an Ethernet unit replies to the last UDP port
it saw for a node, so two sockets sharing SA1 would steal each other's replies (a host name
counts as the address it resolves to; ``connect()`` sessions outside the pool count too).
FINS/TCP PLCs accept few connections (each holds one of the unit's node slots): keep
``max_per_endpoint`` within that.

The pool holds at most ``max_sessions`` sessions: a new endpoint evicts the least recently
used idle one, and :class:`PoolFull` says when every one is in use or being opened. A session
whose first use got no reply is closed when given back (its endpoint backs off like a failed
connect), so hosts that never answer do not keep sockets open.

A maintenance task closes sessions unused for ``idle_timeout`` seconds and checks the others
every ``health_interval`` seconds with CPU UNIT STATUS READ (0601), each check in a task of its
own bounded by the session's timeout; a session failing it is closed. An endpoint whose
connection failed is not retried until its backoff has passed (a ceiling doubling from
``backoff_min`` to ``backoff_max``, the delay drawn between half the ceiling and the ceiling,
so PLCs back after a power cut are not retried in lockstep); calls in the meantime fail fast
with :class:`~aiofins.ConnectionLost`. A borrower waits for a connection being made at most its
timeout (``pool.client(url, timeout=...)``, by default the endpoint's request timeout), then
gets :class:`~aiofins.FinsTimeout`; the connection attempt goes on for the next borrower.
A new session's host name is resolved before the pool's lock is taken (a slow lookup for one
endpoint holds up no other), within the same timeout.

No error of a session's task, a health check or the maintenance reaches the pool's task group
or the application: each becomes a failure of its own endpoint (counted, logged under
``aiofins.pool``, a typed error for the borrowers waiting on it).

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
import enum
import logging
import math
import random
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
    default_addresses,
    needs_lookup,
    peer_link,
    pooled_connect,
    request_timeout,
    url_read_only,
)
from .endpoint import Endpoint, option_value, parse_endpoint
from .protocol.errors import CommandError, ConnectionLost, FinsError, FinsTimeout, leaf_errors
from .protocol.header import FinsAddress
from .protocol.inputs import seconds, whole_number
from .session import SessionStats
from .session.nodes import SOURCE_NODES
from .session.response import SESSION_COUNTERS
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


logger = logging.getLogger("aiofins.pool")

#: The shortest pause of the maintenance task between two passes, whatever the intervals.
MIN_MAINTENANCE_PERIOD = 0.01


class PoolFull(ConnectionLost):
    """Every session the pool may hold (``max_sessions``) is in use or being opened: none
    can be evicted for a new endpoint. Raised at once; try again later."""


class EntryState(enum.Enum):
    """Where a pooled session is in its life. :meth:`_Entry.move` makes every transition."""

    #: Its connection is being made; borrowers wait for it (each at most its own timeout).
    CONNECTING = "connecting"
    #: Open; lent to any number of borrowers at once.
    READY = "ready"
    #: Open and being checked with CPU UNIT STATUS READ while idle; still lent meanwhile.
    CHECKING = "checking"
    #: Lent no more (idle too long, failed its health check or its first use, evicted, or
    #: the pool is closing); its task is closing the session.
    CLOSING = "closing"
    #: The connection could not be made; ``error`` says why (its borrowers get it).
    FAILED = "failed"
    #: The session is closed and its task has ended.
    CLOSED = "closed"

    #: Members are singletons: hash them by identity in C (Enum's own hash is a Python
    #: call, paid per scan by a Poller's lending, ``state in _LENDABLE``).
    __hash__ = object.__hash__


_TRANSITIONS: dict[EntryState, frozenset[EntryState]] = {
    EntryState.CONNECTING: frozenset({EntryState.READY, EntryState.FAILED}),
    EntryState.READY: frozenset({EntryState.CHECKING, EntryState.CLOSING}),
    EntryState.CHECKING: frozenset({EntryState.READY, EntryState.CLOSING}),
    EntryState.CLOSING: frozenset({EntryState.CLOSED}),
    EntryState.FAILED: frozenset(),
    EntryState.CLOSED: frozenset(),
}
#: States in which an entry's client is lent.
_LENDABLE = frozenset({EntryState.READY, EntryState.CHECKING})
#: States in which an entry holds (or is getting) a socket or a serial port.
_LIVE = frozenset(
    {EntryState.CONNECTING, EntryState.READY, EntryState.CHECKING, EntryState.CLOSING}
)


@dataclass(eq=False)
class _Entry:
    """One pooled session (or the attempt to open it)."""

    #: The endpoint's key (link and options: what it addresses and how).
    key: str
    #: Where its frames go (``udp://host:port``): sessions of several keys may share it.
    link: str
    url: str
    src: FinsAddress | None
    dest: FinsAddress | None = None
    state: EntryState = EntryState.CONNECTING
    client: Client | None = None
    error: BaseException | None = None
    #: ``error``'s traceback when it happened (each borrower is handed the error with it).
    error_tb: TracebackType | None = None
    users: int = 0
    #: When a borrower last gave it back (idle closing and eviction go by it).
    last_used: float = 0.0
    #: When its health was last known good (a use or a health check).
    checked_at: float = 0.0
    #: A reply came (normal or not): the link works. Until then, a failed use closes it.
    proven: bool = False
    #: Cancels the connect while it is being made (the pool closes meanwhile).
    connecting: anyio.CancelScope = field(default_factory=anyio.CancelScope)
    #: Set (and replaced) on every transition.
    changed: anyio.Event = field(default_factory=anyio.Event)

    def move(self, to: EntryState) -> None:
        """The one place an entry changes state (``RuntimeError`` for a transition that
        the table does not allow: a bug in the pool)."""
        if to not in _TRANSITIONS[self.state]:
            raise RuntimeError(f"pool entry {self.key}: {self.state.name} -> {to.name}")
        self.state = to
        changed, self.changed = self.changed, anyio.Event()
        changed.set()

    async def wait_while(self, *states: EntryState) -> None:
        """Return once the entry is in none of ``states``."""
        while self.state in states:
            await self.changed.wait()


@dataclass
class EndpointStats:
    """An endpoint's counters, summed over its sessions (see ``SessionStats`` for each).

    The counters (``completed`` to ``evictions``) only grow: those of a session the pool
    closed (idle, failed health check, evicted) stay counted. ``sessions``, ``in_use``,
    ``in_flight`` and the latencies describe the sessions open now. ``connect_failures``
    counts the pool's failed first connects (a session whose first use got no reply
    included) and its sessions' failed reconnects alike; ``errors`` the unexpected errors
    caught at the pool's boundary (logged under ``aiofins.pool``). ``backoff`` is the delay
    drawn after the endpoint's last failure (0 once a connection succeeds).
    """

    sessions: int = 0
    in_use: int = 0
    in_flight: int = 0
    completed: int = 0
    timeouts: int = 0
    cancelled: int = 0
    late_replies: int = 0
    duplicates: int = 0
    unsolicited: int = 0
    mismatched: int = 0
    misdirected: int = 0
    malformed: int = 0
    retries: int = 0
    sid_exhausted: int = 0
    sid_probes: int = 0
    sid_spaces_opened: int = 0
    sid_space_failures: int = 0
    breaker_rejects: int = 0
    busy_retries: int = 0
    end_code_errors: int = 0
    background_errors: int = 0
    connects: int = 0
    connect_failures: int = 0
    disconnects: int = 0
    health_failures: int = 0
    errors: int = 0
    evictions: int = 0
    backoff: float = 0.0
    latency_mean: float = 0.0
    latency_p99: float = 0.0


#: Seconds between two warnings that the pool evicts sessions still in regular use.
_CHURN_WARNING_EVERY = 60.0


def _add_counters(into: EndpointStats, stats: SessionStats) -> None:
    for name in SESSION_COUNTERS:
        setattr(into, name, getattr(into, name) + getattr(stats, name))


@dataclass(frozen=True)
class _Resolved:
    """What a new session to an endpoint needs from name resolution, looked up before the
    pool's lock is taken (a slow lookup for one endpoint delays no other)."""

    #: Where its frames go (``udp://address:port``, see :func:`~aiofins.connection.peer_link`).
    link: str
    #: (dest, source) as connect() would default them (UDP; ``None`` elsewhere).
    addresses: tuple[FinsAddress, FinsAddress] | None


def _users(entry: _Entry) -> int:
    return entry.users


def _last_used(entry: _Entry) -> float:
    return entry.last_used


def _seconds(name: str, value: object, *, allow_low: bool = False) -> float:
    """``value`` as a positive, finite number of seconds (0 too, ``allow_low``)."""
    return seconds(name, value, allow_zero=allow_low)


def _count(name: str, value: object) -> int:
    return whole_number(name, value, 1)


class _Lease:
    """``async with pool.client(url) as client``: one use of an endpoint's client."""

    __slots__ = ("entry", "pool", "read_only", "timeout", "url")

    def __init__(self, pool: Pool, url: str, timeout: float | None) -> None:
        self.pool = pool
        self.url = url
        self.timeout = timeout
        self.entry: _Entry | None = None
        #: The borrower's guard (the pool's, or its URL's ``?read_only=``): borrowers of one
        #: session may differ in it, each gets the client it asked for.
        self.read_only = pool.read_only or ("read_only" in url and url_read_only(url))

    def borrow_ready(self) -> Client | None:
        """The client at once if a ready session can be lent without waiting, else None
        (then :meth:`borrow` waits). A scan loop calls this and :meth:`release` directly:
        no coroutine for the usual case."""
        entry = self.pool._ready_entry(self.url)
        if entry is None:
            return None
        self.entry = entry
        client = entry.client
        if client is None or client.read_only == self.read_only:  # (the usual borrower)
            return client
        return client.with_read_only(self.read_only)

    async def borrow(self) -> Client:
        """The client, once the endpoint's session is ready, where :meth:`borrow_ready` had
        none at once (:meth:`release` gives it back)."""
        entry = await self.pool._acquire(self.url, self.timeout)
        self.entry = entry
        assert entry.client is not None
        return entry.client.with_read_only(self.read_only)

    def release(self) -> None:
        """Give the client back (nothing if none was borrowed)."""
        entry = self.entry
        if entry is not None:
            self.entry = None
            entry.users -= 1
            entry.last_used = self.pool._now()
            if not entry.proven:
                self.pool._first_use_ended(entry)

    async def __aenter__(self) -> Client:
        return self.borrow_ready() or await self.borrow()

    async def __aexit__(self, *exc_info: object) -> None:
        self.release()


class Pool:
    """Clients keyed by endpoint URL: sessions shared among tasks, bounded, health-checked
    and backed off as :mod:`aiofins.pool` describes (on this page, above).

    Every argument is checked when the pool is made (:class:`CommandError`): counts are
    whole numbers from 1, times finite seconds above 0 (``backoff_min`` may be 0: no
    backoff), ``backoff_min <= backoff_max``; other keywords are options of
    :func:`aiofins.connect` for every endpoint, defaults that an endpoint's URL overrides
    (``timeout``, ``retries``, ``read_only``, ...). Among them the resilience of each session:
    ``breaker_threshold`` (calls in a row without an answer that open its circuit breaker,
    default 5, 0: never), ``breaker_cooldown=(min, max)`` (seconds between the open
    breaker's probes, default ``(0.05, 2.0)``) and ``reconnect_backoff=(min, max)``
    (seconds between reconnection attempts, default ``(0.05, 5.0)``); a URL says
    ``?breaker_threshold=0`` for one endpoint. (``backoff_min``/``backoff_max`` are the
    pool's own: how long an endpoint whose connection failed is left alone.)
    """

    def __init__(
        self,
        *,
        max_per_endpoint: int = 1,
        max_sessions: int = 256,
        idle_timeout: float = 300.0,
        health_interval: float = 30.0,
        backoff_min: float = 0.5,
        backoff_max: float = 30.0,
        **connect_options: Any,
    ) -> None:
        self.max_per_endpoint = _count("max_per_endpoint", max_per_endpoint)
        self.max_sessions = _count("max_sessions", max_sessions)
        self.idle_timeout = _seconds("idle_timeout", idle_timeout)
        self.health_interval = _seconds("health_interval", health_interval)
        self.backoff_min = _seconds("backoff_min", backoff_min, allow_low=True)
        self.backoff_max = _seconds("backoff_max", backoff_max, allow_low=True)
        if self.backoff_min > self.backoff_max:
            raise CommandError(
                f"backoff_min ({backoff_min}) must not be above backoff_max ({backoff_max})"
            )
        check_options(connect_options)
        #: Every borrower's client refuses commands that change the PLC (``read_only=True``).
        self.read_only = bool(connect_options.get("read_only", False))
        for name in ("timeout", "tcp_connect_timeout"):
            if name in connect_options:
                option_value(name, connect_options[name])
        self.connect_options = connect_options
        self._entries: dict[str, list[_Entry]] = {}
        #: The same lists as ``_entries``, by the URL text callers use (no parsing per call).
        self._by_url: dict[str, list[_Entry]] = {}
        #: The URL texts of each key in ``_by_url`` (forgotten with the key's last session).
        self._urls: dict[str, list[str]] = {}
        #: key -> (retry_at, ceiling, delay) after a failure.
        self._failures: dict[str, tuple[float, float, float]] = {}
        #: When the pool last warned that it evicts sessions still in regular use.
        self._churn_warned = -math.inf
        self._stats: dict[str, EndpointStats] = {}
        #: Keys without a session whose counters are kept, oldest first.
        self._retired: dict[str, None] = {}
        self._random = random.Random()
        self._tg: TaskGroup | None = None
        self._closed = False
        self._lock = anyio.Lock()
        self._now = anyio.current_time
        self._wake: anyio.Event | None = None

    async def __aenter__(self) -> Pool:
        """Open the pool (again, after it closed: its counters are kept); ``RuntimeError``
        if it is open already."""
        if self._tg is not None:
            raise RuntimeError("the pool is open already: one 'async with pool' at a time")
        self._closed = False
        self._now = event_loop_clock()
        self._wake = anyio.Event()
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
        """Close every session; an exception of the ``async with`` body leaves as it is (the
        pool's own tasks end at their boundaries: nothing of theirs is added to it)."""
        await self.aclose()
        assert self._tg is not None
        tg, self._tg = self._tg, None
        tg.cancel_scope.cancel()
        await tg.__aexit__(None, None, None)
        return None

    async def aclose(self) -> None:
        """Close every session (in-flight calls fail with ``ConnectionLost``; so do borrowers
        waiting for a connection still being made, which is abandoned)."""
        self._closed = True
        entries = [e for lst in self._entries.values() for e in lst]
        for entry in entries:
            if entry.state is EntryState.CONNECTING:
                entry.connecting.cancel()
            elif entry.state in _LENDABLE:
                entry.move(EntryState.CLOSING)
        with anyio.CancelScope(shield=True):
            for entry in entries:
                await entry.wait_while(*_LIVE)
        self._entries.clear()
        self._by_url.clear()
        self._urls.clear()

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
        if not isinstance(url, str):  # CommandError saying what a URL is, not a TypeError
            parse_endpoint(url)
        if timeout is not None and not (  # math.inf: no bound but the connect timeout
            isinstance(timeout, (int, float)) and not isinstance(timeout, bool) and timeout > 0
        ):
            raise CommandError(f"timeout must be a positive number of seconds, got {timeout!r}")
        return _Lease(self, url, timeout)

    def stats(self, url: str | None = None) -> dict[str, EndpointStats]:
        """Per-endpoint counters (all endpoints, or the one of ``url``), by key."""
        keys = [parse_endpoint(url).key] if url else list(self._stats)
        out: dict[str, EndpointStats] = {}
        for key in keys:
            agg = dataclasses.replace(self._stats.get(key, EndpointStats()))
            failure = self._failures.get(key)
            agg.backoff = failure[2] if failure else 0.0
            for entry in self._entries.get(key, []):
                if entry.client is None or entry.state not in _LIVE:
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
        if best.state in _LENDABLE and (best.users == 0 or len(entries) >= self.max_per_endpoint):
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
        if timeout is None:  # the request timeout the endpoint's sessions get
            default = float(self.connect_options.get("timeout", DEFAULT_TIMEOUT))
            timeout = request_timeout(endpoint, default)
        deadline: float | None = None  # for the name lookup and the connection
        resolved: _Resolved | None = None
        while True:  # twice at most: a new session's names are looked up outside the lock
            async with self._lock:
                if deadline is None:
                    # From the borrower's first turn: queueing behind other borrowers (a
                    # Poller starting 1,000 groups at once) is the pool's own work.
                    deadline = self._now() + timeout
                found = await self._choose(endpoint, url, timeout, resolved)
                if found is not None:
                    entry = found
                    entry.users += 1
                    break
            with anyio.CancelScope(deadline=deadline):
                resolved = await self._resolve(endpoint)
            if resolved is None:
                raise FinsTimeout(f"{key}: {endpoint.host} was not resolved within {timeout} s")
        if entry.state is EntryState.CONNECTING:
            try:
                with anyio.CancelScope(deadline=deadline):
                    await entry.wait_while(EntryState.CONNECTING)
            except BaseException:  # the borrower was cancelled: it no longer uses the entry
                entry.users -= 1
                raise
            if entry.state is EntryState.CONNECTING:  # a later borrower may use the attempt
                entry.users -= 1
                raise FinsTimeout(
                    f"{key}: no connection within {timeout} s: a connection attempt is still "
                    "in progress (a later borrower uses it once it succeeds)"
                )
        if entry.state not in _LENDABLE:
            entry.users -= 1
            err = entry.error
            if isinstance(err, FinsError):
                # The one error object of the entry: raised as is, its traceback would grow
                # by every earlier borrower's frames.
                raise err.with_traceback(entry.error_tb)
            if err is None:
                raise ConnectionLost(f"{key}: the session closed")
            raise ConnectionLost(f"{key}: {err}") from err
        return entry

    async def _choose(
        self, endpoint: Endpoint, url: str, timeout: float, resolved: _Resolved | None
    ) -> _Entry | None:
        """The entry to lend for ``endpoint``: an open one, or a new one; ``None`` if a new
        one is needed and its host name is not looked up yet (``resolved``: the caller looks
        it up without the lock, then asks again; an IP address is resolved here, as it
        needs no lookup). Called with the lock held."""
        key = endpoint.key
        entries = [e for e in self._entries.get(key, []) if e.state in _LIVE]
        usable = [e for e in entries if e.state is not EntryState.CLOSING]
        idle = min(usable, key=_users, default=None)
        # one session a serial line, and a FINS/TCP PLC for a fixed tcp_node
        one = endpoint.scheme == "serial" or (
            endpoint.scheme == "tcp" and bool(self.connect_options.get("tcp_node"))
        )
        most = 1 if one else self.max_per_endpoint
        if idle is not None and not (idle.users and len(usable) < most):
            return idle
        retry_at = self._failures.get(key, (0.0, 0.0, 0.0))[0]
        now = self._now()
        if now < retry_at and idle is None:
            raise ConnectionLost(
                f"{key}: last connection attempt failed; retrying in {retry_at - now:.1f} s"
            )
        if idle is not None and self._count(_LIVE) >= self.max_sessions:
            return idle  # the pool is full: share the busy session
        if resolved is None:
            if needs_lookup(endpoint):
                return None  # looked up without the lock, then asked again
            resolved = await self._resolve(endpoint)  # an address: no lookup to wait for
        return await self._open(endpoint, url, timeout, resolved, extra=bool(usable))

    async def _resolve(self, endpoint: Endpoint) -> _Resolved:
        """Look up what a new session to ``endpoint`` needs (without the pool's lock)."""
        link = await peer_link(endpoint)
        if endpoint.scheme != "udp":
            return _Resolved(link, None)
        defaults = self._options_for(endpoint)
        addresses = await default_addresses(endpoint, defaults.get("dest"), defaults.get("src"))
        return _Resolved(link, addresses)

    async def _open(
        self, endpoint: Endpoint, url: str, timeout: float, resolved: _Resolved, *, extra: bool
    ) -> _Entry:
        """A new entry for ``endpoint`` (its session is opened by a task of its own), once
        the pool has room for it (called with the lock held)."""
        await self._make_room(endpoint.key, timeout)
        link = resolved.link
        # held from now on (UDP): no other session's socket, nor extra SID space, takes it
        dest, src = self._addresses_for(endpoint, resolved, extra=extra)
        key = endpoint.key
        entry = _Entry(key, link, url, src, dest)
        entries = self._entries.setdefault(key, [])
        entries.append(entry)
        urls = self._urls.setdefault(key, [])
        if url not in self._by_url and len(urls) < 8:  # a few spellings of one key
            urls.append(url)
            self._by_url[url] = entries
        self._stats.setdefault(key, EndpointStats())
        self._retired.pop(key, None)
        assert self._tg is not None and self._wake is not None
        self._tg.start_soon(self._serve, entry)
        self._wake.set()
        return entry

    def _count(self, states: frozenset[EntryState]) -> int:
        return sum(e.state in states for lst in self._entries.values() for e in lst)

    def _evicting(self, victim: _Entry, key: str) -> None:
        """Log an eviction: DEBUG, and a WARNING (at most one a minute) when the session
        evicted was used within the last ``health_interval``: more endpoints are in regular
        use than ``max_sessions``, and the pool closes and reopens sessions all the time."""
        now = self._now()
        idle = now - victim.last_used
        if idle < self.health_interval and now - self._churn_warned >= _CHURN_WARNING_EVERY:
            self._churn_warned = now
            logger.warning(
                "%s: evicted, though used %.1f s ago, to make room for %s: more endpoints are "
                "in use than max_sessions=%d, so sessions are closed and opened again all the "
                "time; raise Pool(max_sessions=...)",
                victim.key,
                idle,
                key,
                self.max_sessions,
                extra={"endpoint": victim.key},
            )
        else:
            logger.debug(
                "%s: evicted (idle %.1f s) to make room for %s",
                victim.key,
                idle,
                key,
                extra={"endpoint": victim.key},
            )

    async def _make_room(self, key: str, timeout: float) -> None:
        """Evict idle sessions (least recently used first) until a new one fits within
        ``max_sessions``; :class:`PoolFull` if every session is in use or being opened."""
        with anyio.move_on_after(timeout):
            while self._count(_LIVE) >= self.max_sessions:
                idle = [
                    e
                    for lst in self._entries.values()
                    for e in lst
                    if e.state in _LENDABLE and not e.users
                ]
                if idle:
                    victim = min(idle, key=_last_used)
                    self._evicting(victim, key)
                    self._stats[victim.key].evictions += 1
                    victim.move(EntryState.CLOSING)
                closing = [
                    e
                    for lst in self._entries.values()
                    for e in lst
                    if e.state is EntryState.CLOSING
                ]
                if not closing:
                    logger.warning(
                        "%s: refused, all %d sessions are busy",
                        key,
                        self.max_sessions,
                        extra={"endpoint": key},
                    )
                    raise PoolFull(
                        f"{key}: all {self.max_sessions} sessions of the pool are in use or "
                        "being opened (max_sessions); try again later"
                    )
                await closing[0].wait_while(EntryState.CLOSING)
            return
        raise FinsTimeout(f"{key}: no room in the pool within {timeout} s (sessions closing)")

    def _on_link(self, link: str) -> list[_Entry]:
        """The sessions (of any key) open or being opened to ``link``."""
        return [
            e for lst in self._entries.values() for e in lst if e.link == link and e.state in _LIVE
        ]

    def _options_for(self, endpoint: Endpoint) -> dict[str, Any]:
        """The pool's keyword options for a session to ``endpoint``: defaults, so an option
        its URL sets is left to the URL (``?node=`` and ``?dest=`` both set ``dest``;
        ``read_only`` is kept: either one is enough)."""
        options = dict(self.connect_options)
        for name, _ in endpoint.options:
            if name != "read_only":
                options.pop("dest" if name == "node" else name, None)
        return options

    def _addresses_for(
        self, endpoint: Endpoint, resolved: _Resolved, *, extra: bool
    ) -> tuple[FinsAddress | None, FinsAddress | None]:
        """(dest, source) of a new session to ``endpoint``; ``None``: left to connect().

        An Ethernet unit replies to the last UDP port it saw for a source node, so every UDP
        session to one host:port (whatever its key) gets a source node of its own: the one
        connect() would use if no other session there uses it as source or destination,
        else a free one (254 down); it is held in ``SOURCE_NODES`` from now on. A source the
        URL or the pool names is kept for a new key: if another session to the same
        host:port uses its node, the URL is refused (:class:`CommandError`). Both as
        :meth:`SourceNodes.source_for <aiofins.session.nodes.SourceNodes.source_for>` does
        it for connect(). A serial line carries one session: another key for the same
        device is refused while it is open.
        """
        link = resolved.link
        others = self._on_link(link)
        if endpoint.scheme == "serial":
            open_ = [e for e in others if e.state is not EntryState.CLOSING]
            if any(e.key != endpoint.key for e in open_):
                raise CommandError(
                    f"{endpoint.key}: {endpoint.link} is open in this pool with other settings "
                    f"({open_[0].key}); a serial line carries one session"
                )
            return None, None
        if endpoint.scheme == "tcp":
            fixed = self.connect_options.get("tcp_node")
            if fixed and others:  # the unit gives one connection a fixed node
                raise CommandError(
                    f"{endpoint.key}: FINS/TCP node {fixed} (tcp_node) is held by another "
                    f"session to {link} in this pool ({others[0].key}); the PLC refuses a "
                    "second connection asking for it. Leave tcp_node out (the PLC assigns one)"
                )
            return None, None
        if resolved.addresses is None:
            return None, None
        dest, src = resolved.addresses
        named = (endpoint.option("src") or self._options_for(endpoint).get("src")) is not None
        addressed = {e.dest.node for e in others if e.dest is not None}
        src = SOURCE_NODES.source_for(
            link, src, named=named and not extra, avoid=addressed | {dest.node}, where=endpoint.key
        )
        return dest, src

    # -- each session's task: its boundary --------------------------------------------------

    async def _serve(self, entry: _Entry) -> None:
        """Open the entry's session, hold it while it is lent, close it. Ends at a boundary:
        whatever goes wrong becomes a failure of this entry alone."""
        options = self._options_for(parse_endpoint(entry.url))
        if entry.src is not None:
            options["src"] = entry.src
        try:
            with entry.connecting:  # cancelled only while the connection is being made
                async with pooled_connect(entry.url, **options) as client:
                    entry.client = client
                    entry.last_used = entry.checked_at = self._now()
                    self._failures.pop(entry.key, None)
                    entry.move(EntryState.READY)
                    await entry.wait_while(*_LENDABLE)
            if entry.client is None:  # the pool closed while connecting
                entry.error = ConnectionLost(f"{entry.key}: the pool closed while connecting")
        except (OSError, FinsError) as exc:
            self._fail(entry, exc)
        except Exception as exc:  # the boundary: nothing of one endpoint escapes the pool
            self._stats[entry.key].errors += 1
            logger.error(
                "%s: unexpected error in its session",
                entry.key,
                exc_info=True,
                extra={"endpoint": entry.key},
            )
            leaves = leaf_errors(exc)
            error = ConnectionLost(f"{entry.key}: {', '.join(repr(e) for e in leaves)}")
            error.__cause__ = exc
            self._fail(entry, error)
        finally:
            self._settle(entry)

    def _fail(self, entry: _Entry, exc: BaseException) -> None:
        """The entry's session could not be made, or broke: borrowers get ``exc``."""
        entry.error = exc
        entry.error_tb = exc.__traceback__
        if not entry.proven:  # no reply yet: the connection failed, even if it had opened
            self._stats[entry.key].connect_failures += 1
        self._back_off(entry.key)
        logger.info("%s: connection failed: %s", entry.key, exc, extra={"endpoint": entry.key})

    def _back_off(self, key: str) -> None:
        """Next attempt for ``key`` after a jittered delay: a ceiling doubling from
        ``backoff_min`` to ``backoff_max``, the delay uniform between half of it (at least
        ``backoff_min``) and it."""
        ceiling = self._failures.get(key, (0.0, 0.0, 0.0))[1]
        ceiling = min(self.backoff_max, 2 * max(ceiling, self.backoff_min))
        delay = self._random.uniform(max(self.backoff_min, ceiling / 2), ceiling)
        self._failures[key] = (self._now() + delay, ceiling, delay)

    def _settle(self, entry: _Entry) -> None:
        """The entry's task ends: its last transition, its counters kept, its key forgotten
        with its last session (within bounds)."""
        if entry.state is EntryState.CONNECTING:
            if entry.error is None:
                entry.error = ConnectionLost(f"{entry.key}: the connection attempt ended")
            entry.move(EntryState.FAILED)
        else:
            if entry.state in _LENDABLE:
                entry.move(EntryState.CLOSING)
            entry.move(EntryState.CLOSED)
        key = entry.key
        lst = self._entries.get(key)
        if lst is not None and entry in lst:
            lst.remove(entry)
            if entry.src is not None:
                SOURCE_NODES.release(entry.link, entry.src.node)
        if entry.client is not None:  # its counters stay with the endpoint
            _add_counters(self._stats[key], entry.client.session.stats)
        if lst is not None and not lst:
            del self._entries[key]
            for url in self._urls.pop(key, ()):
                self._by_url.pop(url, None)
            self._retired[key] = None
            while len(self._retired) > self.max_sessions:  # counters of many keys: bounded
                old = next(iter(self._retired))
                del self._retired[old]
                self._stats.pop(old, None)
                self._failures.pop(old, None)

    def _first_use_ended(self, entry: _Entry) -> None:
        """A borrower gave back a session that has seen no reply yet: once a use failed
        (no reply), it is closed and its endpoint backs off, as after a failed connect."""
        client = entry.client
        if client is None:
            return
        stats = client.session.stats
        if stats.completed or stats.end_code_errors:
            entry.proven = True
            return
        failed = stats.timeouts or stats.disconnects or stats.connect_failures
        if failed and not entry.users and entry.state in _LENDABLE:
            logger.info(
                "%s: no reply to its first use; closing it",
                entry.key,
                extra={"endpoint": entry.key},
            )
            self._stats[entry.key].connect_failures += 1
            self._back_off(entry.key)
            entry.move(EntryState.CLOSING)

    # -- maintenance ----------------------------------------------------------------------

    async def _maintain(self) -> None:
        """Idle closing and health checks, at a boundary: an error is logged and counted,
        and the loop goes on."""
        period = max(MIN_MAINTENANCE_PERIOD, min(self.health_interval, self.idle_timeout))
        while True:
            if not self._entries:  # nothing to look after: sleep until a session opens
                assert self._wake is not None
                await self._wake.wait()
                self._wake = anyio.Event()
            await anyio.sleep(period)
            try:
                self._maintain_once()
            except Exception:
                logger.error("pool maintenance failed", exc_info=True)

    def _maintain_once(self) -> None:
        """One pass: close idle sessions, start the due health checks (each a task of its
        own: idle closing never waits for them)."""
        now = self._now()
        assert self._tg is not None
        for entries in list(self._entries.values()):
            for entry in list(entries):
                if entry.users or entry.state not in _LENDABLE:
                    continue
                if now - entry.last_used >= self.idle_timeout:
                    logger.info(
                        "%s: closed after %.1f s unused",
                        entry.key,
                        now - entry.last_used,
                        extra={"endpoint": entry.key},
                    )
                    entry.move(EntryState.CLOSING)
                elif (
                    entry.state is EntryState.READY
                    and now - max(entry.last_used, entry.checked_at) >= self.health_interval
                ):
                    entry.move(EntryState.CHECKING)
                    self._tg.start_soon(self._health_check, entry)

    async def _health_check(self, entry: _Entry) -> None:
        """CPU UNIT STATUS READ, bounded by the session's timeout; a failure closes the
        session if nobody uses it. Ends at a boundary."""
        client = entry.client
        assert client is not None
        ok = False
        timeout = client.session.timeout
        try:
            with anyio.move_on_after(timeout):
                await client.cpu_unit_status_read(timeout=timeout)
                ok = True
        except FinsError as exc:
            logger.info(
                "%s: health check failed: %s", entry.key, exc, extra={"endpoint": entry.key}
            )
        except Exception:
            self._stats[entry.key].errors += 1
            logger.error(
                "%s: unexpected error in its health check",
                entry.key,
                exc_info=True,
                extra={"endpoint": entry.key},
            )
        if entry.state is not EntryState.CHECKING:
            return  # closed meanwhile
        if ok:
            entry.checked_at = self._now()
            entry.proven = True
            entry.move(EntryState.READY)
            return
        self._stats[entry.key].health_failures += 1
        entry.move(EntryState.READY if entry.users else EntryState.CLOSING)
