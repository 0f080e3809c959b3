"""Connection URLs: every query option is checked when the URL is parsed (no I/O)."""

from __future__ import annotations

import socket

import anyio
import pytest

import aiofins.connection
from aiofins.connection import connect, peer_link
from aiofins.endpoint import option_value, parse_endpoint
from aiofins.protocol.errors import CommandError, ConnectionLost

from ..virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("udp://127.0.0.1?node=abc", "node must be a whole number, 0..254; got 'abc'"),
        ("tcp://127.0.0.1?node=255", "node must be a whole number, 0..254; got '255'"),
        ("udp://127.0.0.1?timeout=abc", "timeout must be a positive number of seconds"),
        ("udp://127.0.0.1?timeout=0", "timeout must be a positive number of seconds"),
        ("udp://127.0.0.1?timeout=inf", "timeout must be a positive number of seconds"),
        ("serial:///dev/ttyS0?baudrate=abc", "baudrate must be a whole number, at least 1"),
        ("serial:///dev/ttyS0?bytesize=9", "bytesize must be a whole number, 5..8"),
        ("serial:///dev/ttyS0?parity=X", "parity must be one of N, E, O, M, S; got 'X'"),
        ("serial:///dev/ttyS0?stopbits=3", "stopbits must be 1, 1.5 or 2"),
        ("serial:///dev/ttyS0?unit=32", "Host Link unit number must be a whole number, 0..31"),
        ("serial:///dev/ttyS0?response_wait=x", "response wait time must be a whole number"),
        ("serial:///dev/ttyS0?timeout=-1", "timeout must be a positive number"),
        # a blank value was dropped: ?node= addressed node 1, ?timeout= took the default
        ("udp://127.0.0.1?node=", "node must be a whole number, 0..254; got ''"),
        ("udp://127.0.0.1?node=7&timeout=", "timeout must be a positive number of seconds"),
        ("serial:///dev/ttyS0?unit=", "unit number must be a whole number, 0..31; got ''"),
        ("udp://127.0.0.1?dest=", "FINS address '' is not NET.NODE"),
        # ':0' was taken for the default port 9600
        ("udp://127.0.0.1:0", "port must be 1..65535 .* got 0"),
        ("tcp://[::1]:0?node=3", "port must be 1..65535 .* got 0"),
        # dest and src were checked without naming the URL
        ("udp://127.0.0.1?dest=1.2.3.4", "FINS address '1.2.3.4' is not NET.NODE"),
        ("udp://127.0.0.1?src=300.1.1", "network address 300 out of range"),
        ("udp://127.0.0.1?max_sid_spaces=0", "max_sid_spaces must be a whole number, 1..254"),
        ("tcp://127.0.0.1?max_sid_spaces=x", "max_sid_spaces must be a whole number, 1..254"),
        ("serial:///dev/ttyS0?max_sid_spaces=2", "unknown serial option 'max_sid_spaces'"),
        ("udp://h?breaker_threshold=-1", "breaker_threshold must be a whole number, at least 0"),
        ("udp://h?breaker_cooldown=2", "breaker_cooldown must be MIN,MAX seconds"),
        ("tcp://h?reconnect_backoff=5,1", "reconnect_backoff must be MIN,MAX seconds"),
        ("serial:///dev/ttyS0?reconnect_backoff=a,b", "reconnect_backoff must be MIN,MAX"),
    ],
)
def test_bad_option_values_are_refused_naming_the_url(url: str, message: str) -> None:
    with pytest.raises(CommandError, match=message) as info:
        parse_endpoint(url)
    assert str(info.value).startswith(repr(url))


def test_good_option_values_parse() -> None:
    endpoint = parse_endpoint("serial:///dev/ttyS0?baudrate=115200&parity=e&stopbits=1.5&unit=3")
    assert endpoint.option("parity") == "e"
    assert [option_value(k, v) for k, v in endpoint.options] == [115200, "E", 1.5, 3]
    assert option_value("timeout", "0.25") == 0.25 and option_value("node", 7) == 7


@pytest.mark.anyio
async def test_connect_checks_serial_keywords_too(anyio_backend: object) -> None:
    with pytest.raises(CommandError, match="baudrate must be a whole number"):
        async with connect("serial:///dev/ttyS0", baudrate="fast"):
            pass
    with pytest.raises(CommandError, match=r"tcp_node must be a whole number, 0\.\.254"):
        async with connect("tcp://127.0.0.1:1", tcp_node=300):
            pass
    for bad in (0, -1, "soon", float("inf")):
        with pytest.raises(CommandError, match="tcp_connect_timeout must be a positive number"):
            async with connect("tcp://127.0.0.1:1", tcp_connect_timeout=bad):
                pass


@pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)
def test_tcp_connect_timeout_bounds_a_handshake_that_never_comes(backend: str) -> None:
    """A listener that never accepts: the kernel completes the TCP connect, nobody answers
    the FINS/TCP node address request. The attempt ends after tcp_connect_timeout, not the
    default 5 s: exactly 0.3 s of virtual time (trio's MockClock, asyncio on looptime's loop;
    uvloop's clock cannot be made virtual)."""
    out: list[float] = []

    async def main() -> None:
        with socket.socket() as listener:
            listener.bind(("127.0.0.1", 0))
            listener.listen(8)
            url = f"tcp://127.0.0.1:{listener.getsockname()[1]}"
            start = anyio.current_time()
            with pytest.raises(ConnectionLost, match=r"within 0\.3 s"):
                async with connect(url, tcp_connect_timeout=0.3):
                    pass
            out.append(anyio.current_time() - start)

    run_on_virtual_time(main, backend)
    assert out == [pytest.approx(0.3, abs=1e-6)]


def test_ipv6_hosts_keep_their_brackets_in_keys_and_messages() -> None:
    from aiofins.transport.tcp import TcpTransport
    from aiofins.transport.udp import UdpTransport

    assert parse_endpoint("udp://[::1]:9601").key == "udp://[::1]:9601"
    assert UdpTransport("::1", 9601).description == "udp://[::1]:9601"
    assert TcpTransport("::1").description == "tcp://[::1]:9600"
    assert TcpTransport("10.0.0.5").description == "tcp://10.0.0.5:9600"


@pytest.mark.parametrize(
    ("url", "key"),
    [
        ("udp://127.0.0.1", "udp://127.0.0.1:9600"),
        ("udp://127.0.0.1:9600?node=07&timeout=0.30", "udp://127.0.0.1:9600?node=7&timeout=0.3"),
        ("udp://127.0.0.1?timeout=.3&node=7", "udp://127.0.0.1:9600?node=7&timeout=0.3"),
        ("udp://127.0.0.1?dest=3.5&timeout=1", "udp://127.0.0.1:9600?dest=3.5.0&timeout=1.0"),
        (
            "udp://h?reconnect_backoff=0.5,30&breaker_threshold=02",
            "udp://h:9600?breaker_threshold=2&reconnect_backoff=0.5,30.0",
        ),
        ("tcp://h?src=0.10", "tcp://h:9600?src=0.10.0"),
        ("udp://[0:0:0:0:0:0:0:1]:9601?node=1", "udp://[::1]:9601?node=1"),
        ("tcp://[FE80:0::1%eth0]", "tcp://[fe80::1%eth0]:9600"),
        ("udp://PLC.Example", "udp://plc.example:9600"),
        ("udp://h?max_sid_spaces=08&node=1", "udp://h:9600?max_sid_spaces=8&node=1"),
        ("udp://h?max_sid_spaces=4", "udp://h:9600"),  # the default for UDP
        ("tcp://h?max_sid_spaces=4", "tcp://h:9600?max_sid_spaces=4"),
        ("tcp://h?max_sid_spaces=2", "tcp://h:9600"),  # the default for FINS/TCP
        (
            "serial:///dev/ttyS0?parity=o&baudrate=19200",
            "serial:///dev/ttyS0?baudrate=19200&parity=O",
        ),
    ],
)
def test_a_key_names_the_link_and_every_option_in_one_spelling(url: str, key: str) -> None:
    """A pool shares a session by key: node, dest, src and timeout change what is addressed
    or how, so they are part of it (they were left out: every URL of a host:port shared the
    first one's session)."""
    endpoint = parse_endpoint(url)
    assert endpoint.key == key
    assert endpoint.link == key.split("?")[0]


def test_serial_defaults_are_those_connect_uses() -> None:
    """A serial option at its default is left out of the key: the defaults must be the
    transport's."""
    from aiofins.connection import make_transport
    from aiofins.endpoint import SERIAL_DEFAULTS

    transport = make_transport(parse_endpoint("serial:///dev/ttyS0"))
    for name, value in SERIAL_DEFAULTS.items():
        assert getattr(transport, name) == value, name
    assert parse_endpoint("serial:///dev/ttyS0?unit=0&parity=E&baudrate=9600").key == (
        "serial:///dev/ttyS0"
    )
    assert parse_endpoint("serial:///dev/ttyS0?unit=1&parity=e&baudrate=9600").key == (
        "serial:///dev/ttyS0?unit=1"
    )
    assert parse_endpoint("serial:///dev/ttyS0?parity=N&bytesize=8&stopbits=1").key == (
        "serial:///dev/ttyS0?bytesize=8&parity=N&stopbits=1.0"
    )


def test_serial_defaults_to_omrons_host_link_factory_setting_7e2() -> None:
    """A CPU's Host Link port leaves the factory at 9600 baud, 7 data bits, even parity,
    2 stop bits: a first try with a bare URL must not time out on 8N1."""
    from aiofins.connection import make_transport
    from aiofins.transport.serial import SerialTransport

    for transport in (make_transport(parse_endpoint("serial:///dev/ttyS0")), SerialTransport("x")):
        assert isinstance(transport, SerialTransport)
        settings = (transport.baudrate, transport.bytesize, transport.parity, transport.stopbits)
        assert settings == (9600, 7, "E", 2.0)


@pytest.mark.anyio
async def test_max_sid_spaces_from_the_url_or_connect(anyio_backend: object) -> None:
    from aiofins.simulator import VirtualPLC, run_simulator

    async with run_simulator(VirtualPLC(), udp=("127.0.0.1", 0)) as sim:
        base = f"udp://127.0.0.1:{sim.udp_port}"
        async with connect(base) as plc:
            assert plc.session.max_sid_spaces == 4  # UDP's default
        async with connect(f"{base}?max_sid_spaces=3") as plc:
            assert plc.session.max_sid_spaces == 3
            assert await plc.read("D0") == [0]
        async with connect(f"{base}?max_sid_spaces=3", max_sid_spaces=1) as plc:
            assert plc.session.max_sid_spaces == 1  # the keyword wins
        with pytest.raises(CommandError, match=r"max_sid_spaces must be a whole number, 1\.\.254"):
            async with connect(base, max_sid_spaces=0):
                pass  # pragma: no cover


@pytest.mark.parametrize(
    ("url", "link"),
    [
        ("udp://127.0.0.1:9600", "udp://127.0.0.1:9600"),
        ("tcp://10.0.0.5", "tcp://10.0.0.5:9600"),
        ("udp://[0:0:0:0:0:0:0:1]:9601", "udp://[::1]:9601"),
    ],
)
async def test_an_ip_address_is_its_own_peer_link_with_no_lookup(
    anyio_backend: object, monkeypatch: pytest.MonkeyPatch, url: str, link: str
) -> None:
    """Every new UDP session asks where its frames go; for an address that took a worker
    thread's getaddrinfo each, and a Pool opening 1,000 sessions at once queued them."""
    looked_up: list[str] = []

    async def lookup(host: str, port: int, **kwargs: object) -> list[object]:
        looked_up.append(host)
        raise OSError("no lookup expected")

    monkeypatch.setattr(aiofins.connection, "lookup", lookup)
    assert await peer_link(parse_endpoint(url)) == link
    assert looked_up == []
    # a name is still looked up (a failed lookup leaves the link as written)
    assert await peer_link(parse_endpoint("udp://plc.invalid")) == "udp://plc.invalid:9600"
    assert looked_up == ["plc.invalid"]


@pytest.mark.parametrize(
    ("url", "message"),
    [
        # the first value won, silently: here it switched the write guard off
        ("udp://plc?read_only=0&read_only=1", r"option 'read_only' is given twice \('0' and '1'\)"),
        ("tcp://plc?timeout=1&node=3&timeout=1", "option 'timeout' is given twice"),
        ("serial:///dev/ttyS0?baudrate=9600&baudrate=19200", "option 'baudrate' is given twice"),
        ("udp://plc?dest=0.3.0&node=3", r"\?node= and \?dest= both name the PLC's node"),
    ],
)
def test_a_url_that_says_one_thing_twice_is_refused(url: str, message: str) -> None:
    with pytest.raises(CommandError, match=message) as info:
        parse_endpoint(url)
    assert str(info.value).startswith(repr(url))


@pytest.mark.parametrize(
    ("url", "meant"),
    [
        # two slashes: the relative path dev/ttyUSB0 was opened
        ("serial://dev/ttyUSB0", "did you mean serial:///dev/ttyUSB0?"),
        ("serial://ttyUSB0", "did you mean serial:///dev/ttyUSB0?"),
        ("serial:///COM3", "did you mean serial://COM3?"),
        ("serial:/dev/ttyS1", "did you mean serial:///dev/ttyS1?"),
        ("udp:/10.0.0.5", "did you mean udp://10.0.0.5?"),
        ("tcp:10.0.0.5:9600", "did you mean tcp://10.0.0.5:9600?"),
        ("fins://10.0.0.5", "did you mean udp://10.0.0.5?"),
        ("upd://10.0.0.5", "did you mean udp://10.0.0.5?"),
        ("udp://10.0.0.5/plc?node=5", "has no path .*did you mean udp://10.0.0.5\\?node=5\\?"),
        ("udp://admin@10.0.0.5", "FINS has no user name or password"),
        ("udp://10.0.0.5#x", "has no #fragment"),
        ("udp://10.0.0.5?nod=3", "unknown option 'nod'; did you mean 'node'?"),
        ("10.0.0.5", "is not a connection URL .*; did you mean udp://10.0.0.5\\?"),
        ("udp//10.0.0.5", "did you mean udp://10.0.0.5\\?"),
        ("udp://10.0.0.5,10.0.0.6", "is no host name or IP address \\(one PLC per URL"),
        ("udp:// 10.0.0.5", "is no host name or IP address"),
        ("udp://h?timeout=1;node=2", "did you mean udp://h\\?timeout=1&node=2\\? \\(options are"),
        ("udp://h?node=1?timeout=2", "did you mean udp://h\\?node=1&timeout=2\\?"),
        (
            "serial:///dev/ttyUSB0?baudrate=9600,7,E,2",
            "did you mean baudrate=9600&bytesize=7&parity=E&stopbits=2\\?",
        ),
        ("serial:///dev/ttyUSB0?baudrate=19200 8N1", "bytesize=8&parity=N&stopbits=1\\?"),
        ("udp://10.0.0.5?baudrate=9600", "'baudrate': it is an option of serial URLs"),
        ("udp://10.0.0.5?tcp_node=3", r"keyword of connect\(\) only, connect\(url, tcp_node=...\)"),
    ],
)
def test_almost_right_urls_are_refused_with_the_form_meant(url: str, meant: str) -> None:
    with pytest.raises(CommandError, match=meant):
        parse_endpoint(url)


@pytest.mark.parametrize(
    ("url", "device"),
    [
        ("serial:///dev/ttyUSB0", "/dev/ttyUSB0"),
        ("serial://COM3", "COM3"),
        ("serial://socket://127.0.0.1:7000", "socket://127.0.0.1:7000"),
        ("serial://loop://", "loop://"),
    ],
)
def test_serial_devices_as_meant(url: str, device: str) -> None:
    assert parse_endpoint(url).device == device


@pytest.mark.parametrize(
    "url", ["udp://plc-1.example.com.:9601", "tcp://PLC_7", "udp://[fe80::1%eth0]", "tcp://h"]
)
def test_host_names_and_addresses_pass(url: str) -> None:
    assert parse_endpoint(url).host


@pytest.mark.parametrize(
    "where",
    ["connect", "pool", "cli", "gateway"],
)
@pytest.mark.anyio
async def test_one_parser_refuses_a_repeated_option_everywhere(
    anyio_backend: object, where: str
) -> None:
    """``connect()``, ``Pool``, the command line and the gateway's configuration take a URL
    through the one parser: none of them leaves a client writable."""
    url = "udp://127.0.0.1:1?read_only=0&read_only=1"
    message = "option 'read_only' is given twice"
    if where == "connect":
        with pytest.raises(CommandError, match=message):
            async with connect(url):
                pass  # pragma: no cover
    elif where == "pool":
        from aiofins import Pool

        async with Pool() as pool:
            with pytest.raises(CommandError, match=message):
                async with pool.client(url):
                    pass  # pragma: no cover
    elif where == "cli":
        import subprocess
        import sys

        result = subprocess.run(
            [sys.executable, "-m", "aiofins", "write", url, "D0", "1"],
            capture_output=True,
            text=True,
            check=False,
        )
        assert result.returncode != 0 and message in result.stderr, result.stderr
    else:
        from aiofins.gateway.config import ConfigError, parse_config

        text = '[[groups]]\nname = "g"\ninterval = 1\ntags = { a = "D0" }\n'
        text += f'[[plcs]]\nname = "p"\nurl = "{url}"\n'
        with pytest.raises(ConfigError, match=message):
            parse_config(text)
