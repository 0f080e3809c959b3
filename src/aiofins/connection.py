"""``aiofins.connect(url)``: build the transport, session and client for an endpoint.

Node addressing defaults, all overridable:

* UDP: the PLC's node (DA1) is the last octet of its IPv4 address (Omron's automatic
  address conversion; a host name is resolved first), our node (SA1) the last octet of the
  local address that routes to it; ``dest=``/``src=`` (or ``?dest=``/``?src=``/``?node=`` in
  the URL) override them. Our node is one no other session of the process uses towards that
  host:port (a PLC replies to the last port it saw for a node): a second session gets
  another one, and a ``src`` named in use there is refused (see :mod:`.session.nodes`).
* FINS/TCP: both nodes come from the handshake (we ask the PLC to assign ours).
* Host Link: the CPU unit behind the serial port (``0.0.0``) from ``0.0.0``.
"""

from __future__ import annotations

import inspect
import ipaddress
import socket
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import Any

import anyio

from .client import Client
from .endpoint import (
    MAX_SID_SPACES,
    RESILIENCE_SETTINGS,
    SERIAL_DEFAULTS,
    SERIAL_SETTINGS,
    Endpoint,
    node_from_host,
    option_span,
    option_value,
    parse_endpoint,
)
from .hooks import EventHooks
from .protocol.errors import CommandError
from .protocol.header import FinsAddress
from .protocol.inputs import seconds, shown, whole_number
from .protocol.limits import NetworkType, RouteLimits, RouteSpec, limits_for, parse_routes
from .protocol.values import WordOrder
from .session import Session
from .session.nodes import SOURCE_NODES
from .transport.base import Transport, url_host
from .transport.blocking import BlockingTcpTransport, BlockingUdpTransport
from .transport.serial import SerialTransport
from .transport.tcp import DEFAULT_CONNECT_TIMEOUT, TcpTransport
from .transport.udp import UdpTransport

#: Seconds a request may take in all when neither ``timeout=`` nor ``?timeout=`` says.
DEFAULT_TIMEOUT = 2.0


def request_timeout(endpoint: Endpoint, timeout: float = DEFAULT_TIMEOUT) -> float:
    """Seconds a request to ``endpoint`` may take in all: its URL's ``?timeout=``, else
    ``timeout``."""
    text = endpoint.option("timeout")
    return float(option_value("timeout", text)) if text else timeout


def url_read_only(url: str) -> bool:
    """Whether a connection URL asks for a read-only client (``?read_only=1``)."""
    return bool(option_value("read_only", parse_endpoint(url).option("read_only", "0")))


def _address(value: FinsAddress | str | None) -> FinsAddress | None:
    return None if value is None else FinsAddress.of(value)


def local_node_towards(host: str, avoid: int | None = None) -> int:
    """Last octet of the local IPv4 address that routes to ``host`` (no packet is sent); a
    ``host`` that is no IPv4 address gets the fallback (it is not looked up: that would
    block the event loop)."""
    node: int | None = None
    if node_from_host(host) is not None:
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.connect((host, 9600))
                node = node_from_host(probe.getsockname()[0])
        except OSError:
            node = None
    if node is None or node == avoid:
        node = 254 if avoid != 254 else 253
    return node


def make_transport(endpoint: Endpoint, *, blocking: bool = False, **options: Any) -> Transport:
    """The transport for an endpoint (serial settings come from the URL or ``options``;
    ``local_port``, the UDP port to bind, from ``options`` or ``?local_port=``).
    ``blocking``: a transport of :mod:`aiofins.transport.blocking` (UDP and FINS/TCP), for a
    driver without an event loop."""
    if endpoint.scheme == "udp":
        port = options.get("local_port")
        if port is None:
            port = endpoint.option("local_port", "0")
        local_port = int(option_value("local_port", port))
        if blocking:
            return BlockingUdpTransport(endpoint.host, endpoint.port, local_port=local_port)
        return UdpTransport(endpoint.host, endpoint.port, local_port=local_port)
    if endpoint.scheme == "tcp":
        node = int(option_value("tcp_node", options.get("tcp_node", 0)))
        connect_timeout = float(
            option_value(
                "tcp_connect_timeout",
                options.get("tcp_connect_timeout", DEFAULT_CONNECT_TIMEOUT),
            )
        )
        if blocking:
            return BlockingTcpTransport(
                endpoint.host, endpoint.port, node=node, connect_timeout=connect_timeout
            )
        return TcpTransport(
            endpoint.host,
            endpoint.port,
            node=node,
            connect_timeout=connect_timeout,
            gather_writes=bool(options.get("tcp_gather_writes", True)),
        )
    if blocking:
        raise CommandError(f"{endpoint.scheme}:// has no blocking transport (UDP and FINS/TCP do)")
    settings: dict[str, Any] = dict(SERIAL_DEFAULTS)
    settings.update(endpoint.options)
    settings.update({k: v for k, v in options.items() if k in SERIAL_SETTINGS})
    checked: dict[str, Any] = {name: option_value(name, settings[name]) for name in SERIAL_SETTINGS}
    return SerialTransport(endpoint.device, **checked)


async def lookup(host: str, port: int, *, family: int = 0, kind: int = 0) -> list[Any]:
    """``getaddrinfo`` without blocking the event loop: every host name that
    :func:`connect` and the pool look up goes through here (the transports look theirs up
    when they open)."""
    return list(await anyio.getaddrinfo(host, port, family=family, type=kind))


async def _ipv4_of(host: str, port: int) -> str | None:
    """``host`` itself if it is an IPv4 address, else its first IPv4 address (``None``: none)."""
    if node_from_host(host) is not None or ":" in host:
        return host
    try:
        infos = await lookup(host, port, family=socket.AF_INET, kind=socket.SOCK_DGRAM)
    except OSError:
        return None
    return str(infos[0][4][0]) if infos else None


def _ip_address(host: str) -> str | None:
    """``host`` in the one spelling of its IP address; ``None`` if it is a name."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return None


def needs_lookup(endpoint: Endpoint) -> bool:
    """Whether a session to ``endpoint`` needs a host name looked up (:func:`lookup`):
    not for an IP address or a serial device."""
    return endpoint.scheme != "serial" and _ip_address(endpoint.host) is None


async def peer_link(endpoint: Endpoint) -> str:
    """Where a session to ``endpoint`` sends its frames, as sessions are told apart by the
    PLC: a host name is resolved as the UDP transport resolves it (``localhost`` and
    ``127.0.0.1`` are one Ethernet unit, which keeps one reply port per source node, and one
    FINS/TCP node per connection); a serial device, or a name that does not resolve (the
    connect fails on its own), is the link as written."""
    if endpoint.scheme == "serial":
        return endpoint.link
    literal = _ip_address(endpoint.host)
    if literal is not None:  # no lookup: a worker thread's round trip per new session
        return f"{endpoint.scheme}://{url_host(literal)}:{endpoint.port}"
    kind = socket.SOCK_DGRAM if endpoint.scheme == "udp" else socket.SOCK_STREAM
    try:
        infos = await lookup(endpoint.host, endpoint.port, kind=kind)
    except OSError:
        return endpoint.link
    if not infos:
        return endpoint.link
    address = infos[0][4]
    return f"{endpoint.scheme}://{url_host(str(address[0]))}:{address[1]}"


async def default_addresses(
    endpoint: Endpoint,
    dest: FinsAddress | str | None = None,
    src: FinsAddress | str | None = None,
) -> tuple[FinsAddress, FinsAddress]:
    """(dest, source) for an endpoint, from arguments, URL options, or the defaults above.

    A UDP host name is resolved (without blocking the event loop) for the node defaults only;
    the transport resolves it again when it opens.
    """
    d = _address(dest) or _address(endpoint.option("dest"))
    s = _address(src) or _address(endpoint.option("src"))
    if endpoint.scheme == "serial":
        return d or FinsAddress(0, 0, 0), s or FinsAddress(0, 0, 0)
    host = endpoint.host
    if endpoint.scheme == "udp" and (d is None or s is None):
        host = await _ipv4_of(host, endpoint.port) or host
    if d is None:
        node_text = endpoint.option("node")
        node = int(option_value("node", node_text)) if node_text else node_from_host(host)
        d = FinsAddress(0, node if node is not None else 1, 0)
    if s is None:
        if endpoint.scheme == "tcp":
            s = FinsAddress(0, 0, 0)  # assigned by the handshake
        else:
            s = FinsAddress(0, local_node_towards(host, avoid=d.node), 0)
    return d, s


#: (local port, PLC link) of every open session bound to a fixed port: the sockets to
#: several PLCs share the port (each connected to its PLC), but two to one PLC would share
#: its replies.
_FIXED_PORTS: set[tuple[int, str]] = set()


def _claim_fixed_port(port: int, link: str) -> tuple[int, str]:
    key = (port, link)
    if key in _FIXED_PORTS:
        raise CommandError(
            f"local_port={port} towards {link} is bound by another session of this process: "
            "the PLC's replies would reach only one of them; share that session (a Pool) "
            "instead"
        )
    _FIXED_PORTS.add(key)
    return key


#: Keyword options of :func:`connect` beyond its named parameters: serial settings, the
#: client node asked for in the FINS/TCP handshake, the bound on a FINS/TCP connection
#: attempt (connect and handshake), and whether FINS/TCP gathers writes.
TRANSPORT_OPTIONS = SERIAL_SETTINGS | {"tcp_node", "tcp_connect_timeout", "tcp_gather_writes"}


def check_options(options: Mapping[str, Any]) -> None:
    """Refuse option names :func:`connect` does not take, naming them, and values out of
    range or of the wrong type (before anything opens; a :class:`Pool` checks its options
    when it is made, not at its first connection)."""
    unknown = set(options) - CONNECT_OPTIONS
    if unknown:
        raise CommandError(
            f"unknown option(s): {', '.join(sorted(unknown))} "
            f"(known: {', '.join(sorted(CONNECT_OPTIONS))})"
        )
    for name, value in options.items():
        check = _NUMBER_CHECKS.get(name)
        if check is not None and value is not None:
            check(value)
        elif name in TRANSPORT_OPTIONS and name != "tcp_gather_writes":
            option_value(name, value)


#: Checks of :func:`connect`'s options (numbers in the same wording as the URL's).
_NUMBER_CHECKS: dict[str, Callable[[object], object]] = {
    "timeout": lambda v: seconds("timeout", v),
    "retries": lambda v: whole_number("retries", v, 0),
    "max_in_flight": lambda v: whole_number("max_in_flight", v, 1, 255),
    "max_sid_spaces": lambda v: whole_number("max_sid_spaces", v, 1, MAX_SID_SPACES),
    "gct": lambda v: whole_number("gct", v, 0, 255),
    "read_only": lambda v: _flag("read_only", v),
    "hooks": lambda v: _hooks(v),
    "dest": lambda v: FinsAddress.of(v),
    "src": lambda v: FinsAddress.of(v),
    "breaker_threshold": lambda v: whole_number("breaker_threshold", v, 0),
    "breaker_cooldown": lambda v: _pair("breaker_cooldown", v),
    "reconnect_backoff": lambda v: _pair("reconnect_backoff", v),
    "routes": lambda v: parse_routes(v),
    "source_network": lambda v: whole_number("source_network", v, 0, 127),
    "local_port": lambda v: whole_number("local_port", v, 0, 65535),
}


def _pair(name: str, value: object) -> tuple[float, float]:
    """A keyword's ``(min, max)`` seconds (text is a URL's spelling, not a keyword's)."""
    if not isinstance(value, (tuple, list)):
        raise CommandError(f"{name} must be a pair (min, max) of seconds; got {shown(value)}")
    return option_span(name, value)


def _resilience(endpoint: Endpoint | None, given: Mapping[str, Any]) -> dict[str, Any]:
    """The circuit breaker's and the reconnection's settings for the session: each keyword
    given, else the URL's option, else the session's default (left out)."""
    settings: dict[str, Any] = {}
    for name in sorted(RESILIENCE_SETTINGS):
        value = given.get(name)
        text = None if value is not None or endpoint is None else endpoint.option(name)
        if name == "breaker_threshold":
            value = value if text is None else option_value(name, text)
        elif value is not None or text is not None:
            value = option_span(name, value if text is None else text)
        if value is not None:
            settings[name] = value
    return settings


def _sid_spaces(endpoint: Endpoint | None, spaces: int | None) -> int | None:
    """``max_sid_spaces`` as given, else the URL's ``?max_sid_spaces=``, else ``None`` (the
    transport's default)."""
    if spaces is not None or endpoint is None:
        return spaces
    text = endpoint.option("max_sid_spaces")
    return int(option_value("max_sid_spaces", text)) if text else None


def _hooks(value: object) -> EventHooks:
    if not isinstance(value, EventHooks):
        raise CommandError(f"hooks must be an aiofins.EventHooks; got {shown(value)}")
    return value


def _flag(name: str, value: object) -> bool:
    if not isinstance(value, bool):
        raise CommandError(f"{name} must be True or False; got {shown(value)}")
    return value


def connect(
    url: str | None = None,
    *,
    transport: Transport | None = None,
    dest: FinsAddress | str | None = None,
    src: FinsAddress | str | None = None,
    timeout: float | None = None,
    retries: int = 2,
    max_in_flight: int | None = None,
    max_sid_spaces: int | None = None,
    gct: int = 2,
    networks: tuple[NetworkType, ...] = (),
    limits: RouteLimits | None = None,
    routes: Mapping[int, RouteSpec] | str | None = None,
    source_network: int | None = None,
    local_port: int | None = None,
    word_order: WordOrder | str = WordOrder.LOW_FIRST,
    read_only: bool = False,
    hooks: EventHooks | None = None,
    breaker_threshold: int | None = None,
    breaker_cooldown: tuple[float, float] | None = None,
    reconnect_backoff: tuple[float, float] | None = None,
    **transport_options: Any,
) -> Client:
    """A client of a PLC, opened by ``async with aiofins.connect("udp://10.0.0.5") as plc:``
    or by ``plc = aiofins.connect(url)``, ``await plc.open()`` (and closed by
    ``await plc.aclose()``): see :class:`~aiofins.Client`. Nothing is opened or checked
    before then; a bad URL or option is raised on opening.

    ``networks`` names the networks a routed request crosses (their smallest limits apply);
    ``limits`` overrides them altogether. ``routes`` (or ``?routes=3:sysmac_link``) gives
    limits per destination network, for a client that reaches PLCs behind gateways: a
    mapping of network number to :class:`RouteLimits`, a network type or the types the
    route crosses (see docs/plant-networks.md); other networks take ``networks``/``limits``.
    ``source_network`` (or ``?source_network=N``) is our own FINS network, written into
    SNA so that a gateway can route the reply back (a routed request with SNA 0 is answered
    onto the destination's own network, where we are not). ``local_port`` (or
    ``?local_port=9600``) binds the UDP socket to that port, for a PLC whose Ethernet unit
    answers to a fixed port (static address conversion, IP address table); the session then
    has one SID space (``max_sid_spaces`` 1). ``max_in_flight`` caps concurrent requests to the
    PLC (default 5; serial lines carry one at a time). ``max_sid_spaces`` (or
    ``?max_sid_spaces=N``) caps the sockets (UDP, each with a source node of its own) or
    connections (FINS/TCP) the session may open to the PLC when the 256 SIDs of one are all
    in flight or lingering (default 4 over UDP, 2 over FINS/TCP; see docs/session.md).
    Serial settings (``baudrate``,
    ``bytesize``, ``parity``, ``stopbits``, ``unit``, ``response_wait``) come from the URL
    query or keyword arguments. FINS/TCP: ``tcp_node`` asks the PLC for a client node (0: let
    it allocate one); ``tcp_connect_timeout`` bounds a connection attempt, connect and
    handshake (default 5 s; a call waits for it at most its own ``timeout``);
    ``tcp_gather_writes=False`` writes each frame on its own instead of the frames of one
    event-loop step together.

    A keyword argument given here wins over the same option in the URL's query
    (``connect("udp://h?timeout=0.3", timeout=2)`` waits 2 s); ``?node=N`` and ``?dest=``
    give way to ``dest=``. The exception is ``read_only``: either one is enough. (A
    :class:`~aiofins.Pool`'s keyword options are defaults for every endpoint instead: there
    the URL wins.) ``timeout`` defaults to 2 s.

    ``read_only=True`` (or ``?read_only=1`` in the URL; either one is enough) makes a client
    that refuses every command changing the PLC — memory, parameters, program, mode, clock,
    messages, errors and logs, files, forced bits, access right — with
    :class:`~aiofins.ReadOnlyError` before anything is sent (see
    :mod:`aiofins.protocol.guard`). ``hooks`` (:class:`~aiofins.EventHooks`) receive the
    session's request and link events (see docs/observability.md).

    Resilience: after ``breaker_threshold`` calls in a row that got no answer (default 5;
    0: never) the circuit breaker opens and calls fail at once with
    :class:`~aiofins.CircuitOpen` while one probe at a time tests the link, the probes
    ``breaker_cooldown=(min, max)`` seconds apart (default ``(0.05, 2.0)``, doubling); a lost
    link (FINS/TCP, serial) is opened again after ``reconnect_backoff=(min, max)`` seconds
    (default ``(0.05, 5.0)``, doubling). The URL spells them ``?breaker_threshold=2``,
    ``?breaker_cooldown=0.1,5``, ``?reconnect_backoff=0.5,30``. See
    :mod:`aiofins.session.breaker`.

    ``transport=`` instead of a URL runs the client over a transport made by the caller, e.g.
    :class:`~aiofins.transport.MemoryTransport` around a virtual PLC (tests without sockets);
    ``dest`` then defaults to ``0.1.0`` and ``src`` to ``0.254.0``.

    UDP: every session of the process to one host:port has a source node of its own (a PLC
    replies to the last port it saw for a node, so two sockets sharing one steal each
    other's replies). The default (above) is kept unless another session there uses it;
    then the session gets a free node, 254 down. A ``src`` named here or in the URL whose
    node another session to that host:port uses is refused with :class:`CommandError`.
    """

    def opener() -> AbstractAsyncContextManager[Client]:
        return _connect(
            url,
            transport=transport,
            dest=dest,
            src=src,
            timeout=timeout,
            retries=retries,
            max_in_flight=max_in_flight,
            max_sid_spaces=max_sid_spaces,
            gct=gct,
            networks=networks,
            limits=limits,
            routes=routes,
            source_network=source_network,
            local_port=local_port,
            word_order=word_order,
            read_only=read_only,
            hooks=hooks,
            breaker_threshold=breaker_threshold,
            breaker_cooldown=breaker_cooldown,
            reconnect_backoff=reconnect_backoff,
            source_held=False,
            **transport_options,
        )

    where = url if isinstance(url, str) else str(getattr(transport, "description", transport))
    return Client.unopened(opener, where)


def pooled_connect(url: str, **options: Any) -> AbstractAsyncContextManager[Client]:
    """:func:`connect` for a :class:`~aiofins.Pool`'s session: its UDP source (``src=``)
    is held in :data:`~aiofins.session.nodes.SOURCE_NODES` by the pool already, which chose
    it there with :meth:`~aiofins.session.nodes.SourceNodes.source_for`."""
    return _connect(url, source_held=True, **options)


@asynccontextmanager
async def _connect(
    url: str | None = None,
    *,
    transport: Transport | None = None,
    dest: FinsAddress | str | None = None,
    src: FinsAddress | str | None = None,
    timeout: float | None = None,
    retries: int = 2,
    max_in_flight: int | None = None,
    max_sid_spaces: int | None = None,
    gct: int = 2,
    networks: tuple[NetworkType, ...] = (),
    limits: RouteLimits | None = None,
    routes: Mapping[int, RouteSpec] | str | None = None,
    source_network: int | None = None,
    local_port: int | None = None,
    word_order: WordOrder | str = WordOrder.LOW_FIRST,
    read_only: bool = False,
    hooks: EventHooks | None = None,
    breaker_threshold: int | None = None,
    breaker_cooldown: tuple[float, float] | None = None,
    reconnect_backoff: tuple[float, float] | None = None,
    source_held: bool,
    **transport_options: Any,
) -> AsyncIterator[Client]:
    """:func:`connect`; ``source_held``: the caller holds the UDP source node (``src``)."""
    prepared = await prepare(
        url,
        transport=transport,
        dest=dest,
        src=src,
        timeout=timeout,
        retries=retries,
        max_in_flight=max_in_flight,
        max_sid_spaces=max_sid_spaces,
        gct=gct,
        networks=networks,
        limits=limits,
        routes=routes,
        source_network=source_network,
        local_port=local_port,
        word_order=word_order,
        read_only=read_only,
        hooks=hooks,
        breaker_threshold=breaker_threshold,
        breaker_cooldown=breaker_cooldown,
        reconnect_backoff=reconnect_backoff,
        source_held=source_held,
        **transport_options,
    )
    try:
        async with prepared.session as session:
            yield prepared.client(session)
    finally:
        prepared.release()


class Prepared:
    """A connection made ready by :func:`prepare`: its transport and session (not open),
    what its client takes, and what it holds until :meth:`release`."""

    def __init__(
        self,
        session: Session,
        endpoint: Endpoint | None,
        dest_given: bool,
        client_options: dict[str, Any],
        held: tuple[str, int] | None,
        bound: tuple[int, str] | None,
    ) -> None:
        self.session = session
        self.endpoint = endpoint
        self.dest_given = dest_given
        self.client_options = client_options
        self.held = held
        self.bound = bound

    def client(self, session: Session) -> Client:
        """The client on ``session`` (this connection's, or what drives it), once the link
        is open: a FINS/TCP peer's own node is its destination unless one was named."""
        transport = self.session.transport
        endpoint = self.endpoint
        if (
            transport.remote_node is not None
            and not self.dest_given
            and (
                endpoint is None
                or (endpoint.option("dest") is None and endpoint.option("node") is None)
            )
        ):
            session.dest = FinsAddress(0, transport.remote_node, 0)
        return Client(session, **self.client_options)

    def release(self) -> None:
        """Give back the UDP source node and the fixed local port this connection holds."""
        held, self.held = self.held, None
        if held is not None:
            SOURCE_NODES.release(*held)
        bound, self.bound = self.bound, None
        if bound is not None:
            _FIXED_PORTS.discard(bound)


async def prepare(
    url: str | None = None,
    *,
    transport: Transport | None = None,
    dest: FinsAddress | str | None = None,
    src: FinsAddress | str | None = None,
    timeout: float | None = None,
    retries: int = 2,
    max_in_flight: int | None = None,
    max_sid_spaces: int | None = None,
    gct: int = 2,
    networks: tuple[NetworkType, ...] = (),
    limits: RouteLimits | None = None,
    routes: Mapping[int, RouteSpec] | str | None = None,
    source_network: int | None = None,
    local_port: int | None = None,
    word_order: WordOrder | str = WordOrder.LOW_FIRST,
    read_only: bool = False,
    hooks: EventHooks | None = None,
    breaker_threshold: int | None = None,
    breaker_cooldown: tuple[float, float] | None = None,
    reconnect_backoff: tuple[float, float] | None = None,
    source_held: bool,
    blocking: bool = False,
    **transport_options: Any,
) -> Prepared:
    """Everything :func:`connect` does before it opens: options checked, addresses chosen
    (the UDP source node held), the transport (``blocking``: one of
    :mod:`aiofins.transport.blocking`, for a driver without an event loop) and the session
    made."""
    if url is None and transport is None:
        raise CommandError("the connection URL must be text (or give transport=); got None")
    if url is not None and transport is not None:
        raise CommandError("connect() takes a URL or transport=, not both")
    check_options(
        {
            "timeout": timeout,
            "retries": retries,
            "max_in_flight": max_in_flight,
            "max_sid_spaces": max_sid_spaces,
            "gct": gct,
            "read_only": read_only,
            "hooks": hooks,
            "dest": dest,
            "src": src,
            "breaker_threshold": breaker_threshold,
            "breaker_cooldown": breaker_cooldown,
            "reconnect_backoff": reconnect_backoff,
            "routes": routes,
            "source_network": source_network,
            "local_port": local_port,
        }
    )
    check_options(transport_options)
    if routes is None and url is not None:
        routes = parse_endpoint(url).option("routes")
    route_map = parse_routes(routes) if routes is not None else {}
    endpoint: Endpoint | None = None
    guarded = read_only
    held: tuple[str, int] | None = None  # our source node in SOURCE_NODES (UDP)
    if transport is None:
        assert url is not None
        endpoint = parse_endpoint(url)
        guarded = guarded or bool(option_value("read_only", endpoint.option("read_only", "0")))
        d, s = await default_addresses(endpoint, dest, src)
        if local_port is None and endpoint.option("local_port"):
            local_port = int(option_value("local_port", endpoint.option("local_port")))
        if local_port:
            if endpoint.scheme != "udp":
                raise CommandError("local_port binds a UDP socket: it needs a udp:// URL")
            spaces = _sid_spaces(endpoint, max_sid_spaces)
            if spaces is not None and spaces > 1:
                raise CommandError(
                    f"local_port={local_port} binds one socket: max_sid_spaces must be 1, "
                    f"not {spaces}"
                )
            max_sid_spaces = 1
        transport = make_transport(
            endpoint, blocking=blocking, local_port=local_port, **transport_options
        )
        if endpoint.scheme == "udp" and not source_held:
            link = await peer_link(endpoint)
            named = src is not None or endpoint.option("src") is not None
            s = SOURCE_NODES.source_for(link, s, named=named, avoid={d.node}, where=endpoint.key)
            held = (link, s.node)
    else:
        if not isinstance(transport, Transport):
            raise CommandError(f"transport must be a Transport, got {type(transport).__name__}")
        if transport_options:
            raise CommandError(
                f"option(s) {', '.join(sorted(transport_options))} make a transport; "
                "with transport= the transport is already made"
            )
        d = _address(dest) or FinsAddress(0, 1, 0)
        s = _address(src) or FinsAddress(0, 254, 0)
    if source_network is None and endpoint is not None and endpoint.option("source_network"):
        source_network = int(option_value("source_network", endpoint.option("source_network")))
    if source_network and s.network == 0:
        s = FinsAddress(source_network, s.node, s.unit)
    bound: tuple[int, str] | None = None  # our fixed local port and its peer, in _FIXED_PORTS
    try:
        if local_port and endpoint is not None:
            bound = _claim_fixed_port(local_port, await peer_link(endpoint))
        serial = endpoint is not None and endpoint.scheme == "serial"
        route = limits or limits_for(*(networks or ((NetworkType.HOST_LINK,) if serial else ())))
        session = Session(
            transport,
            source=s,
            dest=d,
            gct=gct,
            max_in_flight=5 if max_in_flight is None else max_in_flight,
            timeout=(
                timeout
                if timeout is not None
                else DEFAULT_TIMEOUT
                if endpoint is None
                else request_timeout(endpoint)
            ),
            retries=retries,
            # (a blocking driver has one socket: no SID space opens in the background)
            max_sid_spaces=1 if blocking else _sid_spaces(endpoint, max_sid_spaces),
            hooks=hooks,
            **_resilience(
                endpoint,
                {
                    "breaker_threshold": breaker_threshold,
                    "breaker_cooldown": breaker_cooldown,
                    "reconnect_backoff": reconnect_backoff,
                },
            ),
        )
        return Prepared(
            session,
            endpoint,
            dest is not None,
            {"limits": route, "routes": route_map, "word_order": word_order, "read_only": guarded},
            held,
            bound,
        )
    except BaseException:
        if held is not None:
            SOURCE_NODES.release(*held)
        if bound is not None:
            _FIXED_PORTS.discard(bound)
        raise


#: Every keyword option :func:`connect` takes (what :class:`Pool` passes on to it).
CONNECT_OPTIONS = (
    frozenset(
        name
        for name, parameter in inspect.signature(connect).parameters.items()
        if parameter.kind is inspect.Parameter.KEYWORD_ONLY and name != "transport"
    )
    | TRANSPORT_OPTIONS
)
