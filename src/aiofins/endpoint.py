"""Endpoints: where a PLC is and how to reach it, parsed from a URL.

* ``udp://host[:port]`` — FINS/UDP (default port 9600);
* ``tcp://host[:port]`` — FINS/TCP (default port 9600);
* ``serial://DEVICE?baudrate=9600&parity=E`` — Host Link FINS on a serial port
  (``serial:///dev/ttyUSB0``: three slashes before an absolute path; ``serial://COM3``).

The query's options are those of :data:`OPTIONS`, one table for :func:`aiofins.connect`,
:class:`aiofins.Pool`, the command line and the gateway: ``?dest=1.2.0`` (DNA.DA1.DA2),
``?src=0.10.0`` and ``?node=N`` (the destination node, DA1) on UDP/TCP URLs,
``?max_sid_spaces=N`` the sockets (UDP) or connections (FINS/TCP) a session may open to the
PLC when the 256 SIDs of one are not enough (see docs/session.md), ``?routes=3:sysmac_link``
the limits per destination network, ``?source_network=N`` our own FINS network (SNA) for
routed requests and, on UDP, ``?local_port=9600`` the port to bind (see
docs/plant-networks.md); on every URL
``?timeout=S`` the seconds a call may take, ``?read_only=1`` a read-only client,
``?breaker_threshold=N``, ``?breaker_cooldown=MIN,MAX`` and ``?reconnect_backoff=MIN,MAX``
the circuit breaker and the reconnection (see :mod:`aiofins.session.breaker`); on a serial
URL the line settings, by default Omron's Host Link factory setting 9600 baud, 7 data bits,
even parity, 2 stop bits (7E2), unit 0.

A URL says each thing once: an option given twice (``?read_only=0&read_only=1``), or
``?node=`` beside ``?dest=``, is refused, and so are forms that are almost right
(``serial://dev/ttyUSB0``, ``udp:/10.0.0.5``, a path after the host), each with the form
meant.
"""

from __future__ import annotations

import difflib
import ipaddress
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlsplit

from .protocol.errors import CommandError
from .protocol.header import FinsAddress
from .protocol.inputs import seconds, shown, switch, whole_number
from .protocol.limits import routes_text
from .transport import tcp, udp
from .transport.base import url_host

DEFAULT_PORT = 9600
#: The most SID spaces (UDP sockets with their own source nodes, FINS/TCP connections) one
#: session may be allowed: one per source node a FINS header can carry.
MAX_SID_SPACES = 254

#: What an option's value is once checked: a number, text, or a (min, max) pair of seconds.
OptionValue = int | float | str | tuple[float, float]

_PARITIES = ("N", "E", "O", "M", "S")
_NET = frozenset({"udp", "tcp"})
_ALL = frozenset({"udp", "tcp", "serial"})
_SERIAL = frozenset({"serial"})
_KEYWORD_ONLY: frozenset[str] = frozenset()


@dataclass(frozen=True)
class UrlOption:
    """One option of a connection URL's query (and the keyword of :func:`aiofins.connect`
    of the same name)."""

    #: What it sets, in a few words (for error messages and the docs).
    meaning: str
    #: The URL schemes whose query may carry it; none: a keyword of ``connect`` only.
    schemes: frozenset[str]
    #: ``check(name, value)``: the value checked (text from a URL, or a keyword's value),
    #: or :class:`CommandError` saying what is wrong.
    check: Callable[[str, object], OptionValue]


def _integer(low: int, high: int | None = None, label: str = "") -> Callable[[str, object], int]:
    def check(name: str, value: object) -> int:
        return whole_number(label or name, value, low, high, text=True)

    return check


def _seconds(name: str, value: object) -> float:
    return seconds(name, value, text=True)


def _switch(name: str, value: object) -> bool:
    return switch(name, value)


def _address(name: str, value: object) -> str:
    return str(FinsAddress.parse(str(value)))


def _routes(name: str, value: object) -> str:
    return routes_text(value)


def _stopbits(name: str, value: object) -> float:
    try:
        bits = float(str(value))
    except ValueError:
        bits = 0.0
    if bits not in (1, 1.5, 2):
        raise CommandError(f"stopbits must be 1, 1.5 or 2; got {value!r}")
    return bits


def _parity(name: str, value: object) -> str:
    parity = str(value).upper()
    if parity not in _PARITIES:
        raise CommandError(f"parity must be one of {', '.join(_PARITIES)}; got {value!r}")
    return parity


def _span(name: str, value: object) -> tuple[float, float]:
    """``(min, max)`` seconds, 0 <= min <= max: a pair, or text ``MIN,MAX``."""
    pieces: list[object]
    if isinstance(value, str):
        pieces = [p for p in value.split(",")]
    elif isinstance(value, (tuple, list)):
        pieces = list(value)
    else:
        pieces = [value]
    if len(pieces) == 2:
        try:
            low, high = (seconds(name, p, allow_zero=True, text=True) for p in pieces)
        except CommandError:
            pass
        else:
            if low <= high:
                return (low, high)
    raise CommandError(
        f"{name} must be MIN,MAX seconds with 0 <= MIN <= MAX (a pair (min, max) as a "
        f"keyword); got {shown(value)}"
    )


#: Every option of a connection URL's query and :func:`aiofins.connect`'s keywords of the
#: same name, with its check: the one table of the URL parser (new options go here).
OPTIONS: dict[str, UrlOption] = {
    "dest": UrlOption("the PLC's FINS address NET.NODE.UNIT", _NET, _address),
    "src": UrlOption("our FINS address NET.NODE.UNIT", _NET, _address),
    "node": UrlOption("the PLC's FINS node (DA1), 0..254", _NET, _integer(0, 254)),
    "max_sid_spaces": UrlOption(
        "sockets (UDP) or connections (TCP) a session may open, 1..254",
        _NET,
        _integer(1, MAX_SID_SPACES),
    ),
    "routes": UrlOption(
        "limits per destination network, NET:TYPE[+TYPE],... (3:sysmac_link)", _NET, _routes
    ),
    "source_network": UrlOption(
        "our FINS network (SNA) for routed requests, 0..127", _NET, _integer(0, 127)
    ),
    "local_port": UrlOption(
        "the UDP port to bind (9600 for a PLC answering to a fixed port)",
        frozenset({"udp"}),
        _integer(0, 65535),
    ),
    "timeout": UrlOption("seconds a call may take", _ALL, _seconds),
    "read_only": UrlOption("refuse every command that changes the PLC", _ALL, _switch),
    "breaker_threshold": UrlOption(
        "calls in a row without an answer that open the circuit breaker (0: never)",
        _ALL,
        _integer(0),
    ),
    "breaker_cooldown": UrlOption(
        "MIN,MAX seconds the open breaker waits before a probe (doubling)", _ALL, _span
    ),
    "reconnect_backoff": UrlOption(
        "MIN,MAX seconds between reconnection attempts (doubling)", _ALL, _span
    ),
    "baudrate": UrlOption("serial speed", _SERIAL, _integer(1)),
    "bytesize": UrlOption("serial data bits, 5..8", _SERIAL, _integer(5, 8)),
    "parity": UrlOption("serial parity, N, E, O, M or S", _SERIAL, _parity),
    "stopbits": UrlOption("serial stop bits, 1, 1.5 or 2", _SERIAL, _stopbits),
    "unit": UrlOption(
        "Host Link unit number, 0..31", _SERIAL, _integer(0, 31, "Host Link unit number")
    ),
    "response_wait": UrlOption(
        "Host Link response wait time, 0..15",
        _SERIAL,
        _integer(0, 15, "Host Link response wait time"),
    ),
    "tcp_node": UrlOption(
        "the client node asked for in the FINS/TCP handshake", _KEYWORD_ONLY, _integer(0, 254)
    ),
    "tcp_connect_timeout": UrlOption(
        "seconds a FINS/TCP connection attempt may take", _KEYWORD_ONLY, _seconds
    ),
}

#: Serial line settings, from a ``serial://`` URL's query or keyword arguments of ``connect``.
SERIAL_SETTINGS = frozenset({"baudrate", "bytesize", "parity", "stopbits", "unit", "response_wait"})

#: The circuit breaker's and the reconnection's settings (URL options and ``connect``,
#: ``Pool`` keywords alike; see :mod:`aiofins.session.breaker`).
RESILIENCE_SETTINGS = frozenset({"breaker_threshold", "breaker_cooldown", "reconnect_backoff"})

#: Serial settings a ``serial://`` URL leaves out (what ``connect`` opens the line with):
#: Omron's Host Link factory setting, 9600 baud 7E2, unit 0.
SERIAL_DEFAULTS: dict[str, int | float | str] = {
    "baudrate": 9600,
    "bytesize": 7,
    "parity": "E",
    "stopbits": 2.0,
    "unit": 0,
    "response_wait": 0,
}


def option_value(name: str, value: object) -> int | float | str:
    """The value of a URL query option (or ``connect`` keyword) ``name``, checked; a
    ``MIN,MAX`` option's in its one spelling (``"0.1,2.0"``: :func:`option_span` gives the
    pair).

    :class:`CommandError` says what is wrong (``?node=abc``, ``?baudrate=-1``, ...).
    """
    option = OPTIONS.get(name)
    if option is None:
        return str(value)
    checked = option.check(name, value)
    if isinstance(checked, tuple):
        return ",".join(str(part) for part in checked)
    return checked


def option_span(name: str, value: object) -> tuple[float, float]:
    """The ``(min, max)`` seconds of a ``MIN,MAX`` option (``?breaker_cooldown=0.1,2``)."""
    return _span(name, value)


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
        among URLs with the same key. A serial setting at its default is left out
        (``serial:///dev/ttyS0?baudrate=9600`` is ``serial:///dev/ttyS0``), and so is
        ``max_sid_spaces`` at its default for the scheme. ``read_only`` is
        left out: it changes what a borrower may send, not how, and each borrower of the
        shared session gets its own guard (:meth:`Client.with_read_only`)."""
        seen = {
            name: _canonical(name, value) for name, value in self.options if name != "read_only"
        }
        if self.scheme == "serial":
            seen = {n: v for n, v in seen.items() if v != _SERIAL_DEFAULT_TEXT.get(n)}
        elif seen.get("max_sid_spaces") == str(_DEFAULT_SID_SPACES[self.scheme]):
            del seen["max_sid_spaces"]
        if not seen:
            return self.link
        query = "&".join(f"{name}={seen[name]}" for name in sorted(seen))
        return f"{self.link}?{query}"

    def option(self, name: str, default: str | None = None) -> str | None:
        """The text of option ``name`` in the URL's query, ``default`` if it has none."""
        for key, value in self.options:
            if key == name:
                return value
        return default

    def __str__(self) -> str:
        return self.key


_SCHEMES = ("udp", "tcp", "serial")
#: Schemes other FINS libraries and tools use, and what to write here instead.
_OTHER_SCHEMES = {"fins": "udp", "finsudp": "udp", "fins+udp": "udp", "udp4": "udp"}
_OTHER_SCHEMES |= {"finstcp": "tcp", "fins+tcp": "tcp", "tcp4": "tcp"}
_OTHER_SCHEMES |= {"com": "serial", "tty": "serial", "hostlink": "serial", "rs232": "serial"}
_SLASHES_LEFT_OUT = re.compile(r"^(udp|tcp|serial):/?([^/].*)$", re.IGNORECASE)
#: A Windows port, ``COM3``, which is no path.
_COM_PORT = re.compile(r"^COM\d+$", re.IGNORECASE)


#: A host name (letters, digits, ``-``, ``_``, dots) or an IPv4 address: what a bare
#: ``10.0.0.5`` given for a URL looks like.
_HOST_NAME = re.compile(r"^[A-Za-z0-9_]([A-Za-z0-9_.-]*[A-Za-z0-9_])?\.?$")
_SCHEME_MISSPELT = re.compile(r"^(udp|tcp|serial)[:/]*(.+)$", re.IGNORECASE)
#: Line settings written as one value (``9600,7,E,2``, ``9600 7E2``, ``9600-8-N-1``).
_LINE_IN_ONE = re.compile(
    r"^(\d+)[,\s/-]*([5-8])[,\s/-]*([NEOMS])[,\s/-]*(1\.5|1|2)$", re.IGNORECASE
)


def _meant_without_slashes(url: str) -> str:
    """``; did you mean udp://10.0.0.5?`` for ``udp:10.0.0.5``, ``udp:/10.0.0.5``,
    ``udp//10.0.0.5`` or a bare ``10.0.0.5``."""
    text = url.strip()
    meant = _SLASHES_LEFT_OUT.match(text) or _SCHEME_MISSPELT.match(text)
    if meant is None:
        host = text.split("?", 1)[0]
        return f"; did you mean udp://{text}?" if _HOST_NAME.match(host.split(":")[0]) else ""
    scheme, rest = meant.group(1).lower(), meant.group(2)
    if scheme == "serial" and not _COM_PORT.match(rest):
        rest = "/" + rest.lstrip("/")
    return f"; did you mean {scheme}://{rest}?"


def _refuse(url: str, message: str) -> CommandError:
    return CommandError(f"{url!r}: {message}")


def parse_endpoint(url: str) -> Endpoint:
    """Parse a connection URL; :class:`CommandError` names what is wrong and, for a form
    that is almost right, the form meant."""
    if not isinstance(url, str):
        raise CommandError(
            f"the connection URL must be text such as 'udp://HOST'; got {type(url).__name__}"
        )
    if "://" not in url:
        raise CommandError(
            f"{url!r} is not a connection URL (udp://HOST[:PORT], tcp://HOST[:PORT] or "
            f"serial:///DEVICE){_meant_without_slashes(url)}"
        )
    try:
        parts = urlsplit(url)
    except ValueError as exc:  # e.g. an unclosed [ of an IPv6 address
        raise CommandError(f"{url!r}: {exc}") from None
    scheme = parts.scheme.lower()
    if scheme not in _SCHEMES:
        instead = _OTHER_SCHEMES.get(scheme) or next(
            iter(difflib.get_close_matches(scheme, _SCHEMES, n=1)), None
        )
        hint = f"; did you mean {instead}://{url.split('://', 1)[1]}?" if instead else ""
        raise _refuse(url, f"unknown scheme {scheme!r}{hint} (use udp, tcp or serial)")
    if parts.fragment:
        raise _refuse(url, f"a connection URL has no #fragment ({parts.fragment!r})")
    options = _options(url, parts.query, scheme)
    if scheme == "serial":
        device = _device(url, parts.netloc, parts.path)
        return Endpoint("serial", device=device, options=options)
    if parts.username is not None or parts.password is not None:
        raise _refuse(url, "FINS has no user name or password: leave out the 'user@'")
    host = _canonical_host(parts.hostname or "")
    if not host:
        raise _refuse(url, f"missing host; e.g. {scheme}://192.168.250.1")
    try:
        port = DEFAULT_PORT if parts.port is None else parts.port
    except ValueError as exc:
        raise _refuse(url, "bad port") from exc
    if not port:  # ``:0`` was taken for the default port
        raise _refuse(url, "port must be 1..65535 (9600 if left out); got 0")
    if not _HOST_NAME.match(host) and ":" not in host:  # (an IPv6 address has colons)
        raise _refuse(
            url,
            f"{host!r} is no host name or IP address (one PLC per URL, no spaces)",
        )
    if parts.path not in ("", "/"):
        query = f"?{parts.query}" if parts.query else ""
        raise _refuse(
            url,
            f"a {scheme} URL has no path ({parts.path!r}); did you mean "
            f"{scheme}://{parts.netloc}{query}?",
        )
    return Endpoint(scheme, host=host, port=port, options=options)


def _options(url: str, query: str, scheme: str) -> tuple[tuple[str, str], ...]:
    """The query's options, each checked: known for the scheme, given once, a good value."""
    # A bare ``?read_only`` turns the guard on (a guard asked for must never be ignored);
    # any other blank option (``?node=``) is refused by its check, not dropped: it would
    # address node 1 or take the default.
    options = tuple(
        (key, "1" if key == "read_only" and not value else value)
        for key, value in parse_qsl(query, keep_blank_values=True)
    )
    given: dict[str, str] = {}
    for key, value in options:
        option = OPTIONS.get(key)
        if option is None or scheme not in option.schemes:
            raise _refuse(url, _unknown(key, scheme))
        if key in given:
            raise _refuse(
                url,
                f"option {key!r} is given twice ({given[key]!r} and {value!r}): a URL says "
                "each thing once; keep the one you mean",
            )
        given[key] = value
        try:
            option.check(key, value)
        except CommandError as exc:
            raise _refuse(url, f"{exc}{_meant_value(url, key, value)}") from None
    if "node" in given and "dest" in given:
        raise _refuse(
            url,
            f"?node= and ?dest= both name the PLC's node: give dest=NET.NODE.UNIT alone "
            f"(node={given['node']} is dest=0.{given['node']}.0)",
        )
    return options


def _meant_value(url: str, key: str, value: str) -> str:
    """A form meant for an option value that did not parse: options joined by ``;`` or a
    second ``?`` instead of ``&``, line settings in one value."""
    if ";" in value or "?" in value:
        base, _, query = url.partition("?")
        joined = query.replace(";", "&").replace("?", "&")
        return f"; did you mean {base}?{joined}? (options are joined by &)"
    line = _LINE_IN_ONE.match(value) if key == "baudrate" else None
    if line:
        baud, size, parity, stop = line.groups()
        return (
            f"; did you mean baudrate={baud}&bytesize={size}&parity={parity.upper()}"
            f"&stopbits={stop}?"
        )
    return ""


def _unknown(key: str, scheme: str) -> str:
    known = sorted(name for name, option in OPTIONS.items() if scheme in option.schemes)
    kind = "serial option" if scheme == "serial" else "option"
    message = f"unknown {kind} {key!r}"
    option = OPTIONS.get(key)
    if option is not None and option.schemes:
        message += f": it is an option of {' and '.join(sorted(option.schemes))} URLs"
    elif option is not None:
        message += f": it is a keyword of connect() only, connect(url, {key}=...)"
    else:
        close = difflib.get_close_matches(key.lower(), known, n=1, cutoff=0.6)
        if close:
            message += f"; did you mean {close[0]!r}?"
    return f"{message} (known: {', '.join(known)})"


def _device(url: str, netloc: str, path: str) -> str:
    """The serial device of a ``serial://`` URL: ``serial:///dev/ttyUSB0`` (an absolute
    path after the third slash), ``serial://COM3``, or a pyserial URL
    (``serial://socket://host:port``)."""
    if not netloc:
        if not path:
            raise _refuse(url, "serial URL needs a device, e.g. serial:///dev/ttyUSB0")
        if path.startswith("/") and _COM_PORT.match(path[1:]):
            raise _refuse(url, f"did you mean serial://{path[1:]}? (a Windows port is no path)")
        return path
    if netloc.endswith(":"):  # a pyserial URL: socket://, rfc2217://, loop://
        return netloc + path
    if path or not _COM_PORT.match(netloc):
        # ``serial://dev/ttyUSB0`` names the relative path dev/ttyUSB0, a device nobody
        # means: the host part of a URL is no directory.
        meant = f"/{netloc}{path}" if path else f"/dev/{netloc}"
        raise _refuse(
            url,
            f"did you mean serial://{meant}? (a device path follows three slashes: "
            f"serial:// and then the absolute path{'' if path else ' of the device'})",
        )
    return netloc


def _canonical_host(host: str) -> str:
    """An IP address in one spelling (``[0:0::1]`` is ``::1``); a name as it is."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return host


def _canonical(name: str, value: object) -> str:
    """One spelling of an option's value (``?node=07`` is ``node=7``, ``?dest=3.5`` ...)."""
    return str(option_value(name, value))


#: SID spaces a session of each scheme opens at most unless told (the transport's default).
_DEFAULT_SID_SPACES = {"udp": udp.DEFAULT_SID_SPACES, "tcp": tcp.DEFAULT_SID_SPACES}

_SERIAL_DEFAULT_TEXT = {name: _canonical(name, str(v)) for name, v in SERIAL_DEFAULTS.items()}


def node_from_host(host: str) -> int | None:
    """The FINS node number Omron derives from an IPv4 address: its last octet (1..254)."""
    pieces = host.split(".")
    if len(pieces) != 4 or not all(p.isdigit() for p in pieces):
        return None
    last = int(pieces[3])
    return last if 1 <= last <= 254 else None
