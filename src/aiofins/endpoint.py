"""Endpoints: where a PLC is and how to reach it, parsed from a URL.

* ``udp://host[:port]`` — FINS/UDP (default port 9600);
* ``tcp://host[:port]`` — FINS/TCP (default port 9600);
* ``serial://DEVICE?baudrate=115200&unit=0&bytesize=8&parity=N&stopbits=1`` — Host Link
  FINS on a serial port (``serial:///dev/ttyUSB0`` or ``serial://COM3``).

Query parameters on UDP/TCP URLs set node addressing: ``?dest=1.2.0`` (DNA.DA1.DA2),
``?src=0.10.0`` and ``?node=N`` (the destination node, DA1), and ``?max_sid_spaces=N`` the
sockets (UDP) or connections (FINS/TCP) a session may open to the PLC when the 256 SIDs of one
are not enough (see docs/session.md). On every URL, ``?timeout=S`` sets the seconds a call
may take and ``?read_only=1`` makes a read-only client.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlsplit

from .protocol.errors import CommandError
from .protocol.header import FinsAddress
from .protocol.inputs import seconds, switch, whole_number
from .transport import tcp, udp
from .transport.base import url_host

DEFAULT_PORT = 9600
#: The most SID spaces (UDP sockets with their own source nodes, FINS/TCP connections) one
#: session may be allowed: one per source node a FINS header can carry.
MAX_SID_SPACES = 254

#: Serial line settings, from a ``serial://`` URL's query or keyword arguments of ``connect``.
SERIAL_SETTINGS = frozenset({"baudrate", "bytesize", "parity", "stopbits", "unit", "response_wait"})
_SERIAL_KEYS = SERIAL_SETTINGS | {"timeout", "read_only"}
_NET_KEYS = {"dest", "src", "node", "timeout", "read_only", "max_sid_spaces"}

_PARITIES = ("N", "E", "O", "M", "S")

#: Serial settings a ``serial://`` URL leaves out (what ``connect`` opens the line with).
SERIAL_DEFAULTS: dict[str, int | float | str] = {
    "baudrate": 9600,
    "bytesize": 8,
    "parity": "N",
    "stopbits": 1.0,
    "unit": 0,
    "response_wait": 0,
}


def _integer(name: str, value: object, low: int, high: int | None = None) -> int:
    return whole_number(name, value, low, high, text=True)


def option_value(name: str, value: object) -> int | float | str:
    """The value of a URL query option (or ``connect`` keyword) ``name``, checked.

    :class:`CommandError` says what is wrong (``?node=abc``, ``?baudrate=-1``, ...).
    """
    if name in ("timeout", "tcp_connect_timeout"):
        return seconds(name, value, text=True)
    if name == "read_only":
        return switch(name, value)
    if name in ("node", "tcp_node"):
        return _integer(name, value, 0, 254)
    if name == "max_sid_spaces":
        return _integer(name, value, 1, MAX_SID_SPACES)
    if name == "baudrate":
        return _integer("baudrate", value, 1)
    if name == "bytesize":
        return _integer("bytesize", value, 5, 8)
    if name == "unit":
        return _integer("Host Link unit number", value, 0, 31)
    if name == "response_wait":
        return _integer("Host Link response wait time", value, 0, 15)
    if name == "stopbits":
        try:
            bits = float(str(value))
        except ValueError:
            bits = 0.0
        if bits not in (1, 1.5, 2):
            raise CommandError(f"stopbits must be 1, 1.5 or 2; got {value!r}")
        return bits
    if name in ("dest", "src"):
        return str(FinsAddress.parse(str(value)))
    if name == "parity":
        parity = str(value).upper()
        if parity not in _PARITIES:
            raise CommandError(f"parity must be one of {', '.join(_PARITIES)}; got {value!r}")
        return parity
    return str(value)


@dataclass(frozen=True)
class Endpoint:
    """A parsed connection URL. ``key`` identifies it in a pool."""

    scheme: str
    host: str = ""
    port: int = DEFAULT_PORT
    device: str = ""
    options: tuple[tuple[str, str], ...] = field(default=())

    @property
    def link(self) -> str:
        """Where frames go: ``scheme://host:port`` (``serial://device``), options left out.

        Every session to one link shares what the link has only once: a UDP peer's reply
        port per source node, a serial line.
        """
        if self.scheme == "serial":
            return f"serial://{self.device}"
        return f"{self.scheme}://{url_host(self.host)}:{self.port}"

    @property
    def key(self) -> str:
        """The link and every option that changes what is addressed or how, in one
        spelling: ``udp://h:9600?dest=3.5.0&timeout=0.3``. A pool shares a session only
        among URLs with the same key. An option given twice counts by its first value (the
        one :meth:`option` and ``connect`` use); a serial setting at its default is left out
        (``serial:///dev/ttyS0?baudrate=9600`` is ``serial:///dev/ttyS0``), and so is
        ``max_sid_spaces`` at its default for the scheme. ``read_only`` is
        left out: it changes what a borrower may send, not how, and each borrower of the
        shared session gets its own guard (:meth:`Client.with_read_only`)."""
        seen: dict[str, str] = {}
        for name, value in self.options:
            if name not in seen and name != "read_only":
                seen[name] = _canonical(name, value)
        if self.scheme == "serial":
            seen = {n: v for n, v in seen.items() if v != _SERIAL_DEFAULT_TEXT.get(n)}
        elif seen.get("max_sid_spaces") == str(_DEFAULT_SID_SPACES[self.scheme]):
            del seen["max_sid_spaces"]
        if not seen:
            return self.link
        query = "&".join(f"{name}={seen[name]}" for name in sorted(seen))
        return f"{self.link}?{query}"

    def option(self, name: str, default: str | None = None) -> str | None:
        for key, value in self.options:
            if key == name:
                return value
        return default

    def __str__(self) -> str:
        return self.key


def parse_endpoint(url: str) -> Endpoint:
    """Parse a connection URL; :class:`CommandError` names what is wrong."""
    if not isinstance(url, str):
        raise CommandError(
            f"the connection URL must be text such as 'udp://HOST'; got {type(url).__name__}"
        )
    if "://" not in url:
        raise CommandError(
            f"{url!r} is not a connection URL; use udp://HOST[:PORT], tcp://HOST[:PORT] or "
            "serial://DEVICE?baudrate=N"
        )
    try:
        parts = urlsplit(url)
    except ValueError as exc:  # e.g. an unclosed [ of an IPv6 address
        raise CommandError(f"{url!r}: {exc}") from None
    scheme = parts.scheme.lower()
    # A bare ``?read_only`` turns the guard on (a guard asked for must never be ignored);
    # any other blank option (``?node=``) is refused by its check, not dropped: it would
    # address node 1 or take the default.
    options = tuple(
        (key, "1" if key == "read_only" and not value else value)
        for key, value in parse_qsl(parts.query, keep_blank_values=True)
    )
    if scheme == "serial":
        device = (parts.netloc + parts.path) if parts.netloc else parts.path
        if not device:
            raise CommandError(f"{url!r}: serial URL needs a device, e.g. serial:///dev/ttyUSB0")
        for key, value in options:
            if key not in _SERIAL_KEYS:
                raise CommandError(
                    f"{url!r}: unknown serial option {key!r}; known: "
                    f"{', '.join(sorted(_SERIAL_KEYS))}"
                )
            _check(url, key, value)
        return Endpoint("serial", device=device, options=options)
    if scheme not in ("udp", "tcp"):
        raise CommandError(f"{url!r}: unknown scheme {scheme!r}; use udp, tcp or serial")
    host = _canonical_host(parts.hostname or "")
    if not host:
        raise CommandError(f"{url!r}: missing host")
    try:
        port = DEFAULT_PORT if parts.port is None else parts.port
    except ValueError as exc:
        raise CommandError(f"{url!r}: bad port") from exc
    if not port:  # ``:0`` was taken for the default port
        raise CommandError(f"{url!r}: port must be 1..65535 (9600 if left out); got 0")
    for key, value in options:
        if key not in _NET_KEYS:
            raise CommandError(
                f"{url!r}: unknown option {key!r}; known: {', '.join(sorted(_NET_KEYS))}"
            )
        _check(url, key, value)
    return Endpoint(scheme, host=host, port=port, options=options)


def _canonical_host(host: str) -> str:
    """An IP address in one spelling (``[0:0::1]`` is ``::1``); a name as it is."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return host


def _canonical(name: str, value: str) -> str:
    """One spelling of an option's value (``?node=07`` is ``node=7``, ``?dest=3.5`` ...)."""
    return str(option_value(name, value))


#: SID spaces a session of each scheme opens at most unless told (the transport's default).
_DEFAULT_SID_SPACES = {"udp": udp.DEFAULT_SID_SPACES, "tcp": tcp.DEFAULT_SID_SPACES}

_SERIAL_DEFAULT_TEXT = {name: _canonical(name, str(v)) for name, v in SERIAL_DEFAULTS.items()}


def _check(url: str, key: str, value: str) -> None:
    try:
        option_value(key, value)
    except CommandError as exc:
        raise CommandError(f"{url!r}: {exc}") from None


def node_from_host(host: str) -> int | None:
    """The FINS node number Omron derives from an IPv4 address: its last octet (1..254)."""
    pieces = host.split(".")
    if len(pieces) != 4 or not all(p.isdigit() for p in pieces):
        return None
    last = int(pieces[3])
    return last if 1 <= last <= 254 else None
