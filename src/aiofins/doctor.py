"""``aiofins doctor URL``: diagnose a connection to a PLC as an expert would, one finding at a
time, each with its fix.

The checks, in order (each probe bounded by ``timeout`` seconds):

1. **Transports**: does the port answer FINS/UDP, FINS/TCP, both or neither (a CPU UNIT
   STATUS READ, 06 01, sent by hand on UDP; a FINS/TCP connect, handshake and the same
   read on TCP). A UDP port nobody listens on is told apart from a silent one when the
   network says so (ICMP port unreachable).
2. **Destination node** (DA1): the URL's (``?node=``/``?dest=``), then the IP address's last
   octet (Omron's automatic address conversion). If neither answers, DA1 0 (the local PLC)
   is tried: a reply carries the PLC's own node as its source (SA1), which is then named.
3. **Reply port**: a probe goes out from an ephemeral port while a second socket listens on
   the PLC's FINS port (9600) here. A reply to the sending port is dynamic address
   conversion; a reply to the fixed port is static conversion or an IP address table: the
   client must bind that port, with one socket (``?local_port=9600&max_sid_spaces=1``).
4. **CPU**: its model (CPU UNIT DATA READ, 05 01) and mode and errors (06 01).
5. **Memory**: one word read at ``address`` (``D0``). An NJ/NX CPU answers FINS only for
   variables AT-mapped to CJ-series memory (the simulator's NJ answers any other address
   with end code 1101, area missing; see :attr:`aiofins.simulator.VirtualPLC.at_mapped`).
6. **Writes**: read-only by default (nothing is written; the PLC's mode and the URL's
   ``read_only`` are reported). With ``write_test=True`` the word read at ``address`` is
   written back with its own value, and a refusal is explained: network write protection
   (2102), the access right held by another node (3001), read-only area (2101), mode (22xx).
   Only ask for it where that word is yours: a program writing it between the read and the
   write-back would see its value put back.
7. **Round trip**: the median of ``rounds`` CPU UNIT STATUS READs, timed on the event loop's
   clock.

``network=`` runs the probes on an in-memory network (:mod:`aiofins.memnet`, with
``local_host`` our address there) instead of the operating system's sockets.
"""

from __future__ import annotations

import enum
import ipaddress
import socket
import statistics
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any
from urllib.parse import urlencode

import anyio

from .connection import connect
from .endpoint import Endpoint, node_from_host, option_value, parse_endpoint
from .protocol.commands.machine import CpuUnitData
from .protocol.commands.status import CpuMode, CpuUnitStatus
from .protocol.errors import CommandError, EndCodeError, FinsError, FinsTimeout
from .protocol.header import FinsAddress, ResponseFrame, build_command
from .protocol.inputs import switch
from .transport.tcp import TcpTransport
from .transport.udp import UdpTransport

if TYPE_CHECKING:
    from .client import Client
    from .memnet import MemoryNetwork

__all__ = [
    "EXIT_OK",
    "EXIT_PROBLEM",
    "EXIT_UNREACHABLE",
    "Diagnosis",
    "Finding",
    "Severity",
    "diagnose",
]

#: Exit code of ``aiofins doctor``: no problem found (warnings may have been printed).
EXIT_OK = 0
#: Exit code: the PLC answers, but at least one finding is a problem (each names its fix).
EXIT_PROBLEM = 3
#: Exit code: no transport, node or port tried got an answer from the PLC.
EXIT_UNREACHABLE = 4

#: CPU UNIT STATUS READ (06 01): the probe every check sends (no parameters, any mode).
_STATUS_READ = (0x06, 0x01)
#: End codes a write test explains, with the fix.
_WRITE_REFUSALS: dict[int, tuple[str, str]] = {
    0x2102: (
        "network write protection: the CPU refuses FINS writes from this node",
        "allow this node in the CPU's FINS write protection settings (PLC Setup: "
        "'FINS write protection', nodes excluded), or turn the protection off",
    ),
    0x3001: (
        "another node holds the access right (a programming tool online, or an "
        "ACCESS RIGHT ACQUIRE not released)",
        "release it there (or wait for it), then write",
    ),
    0x2101: (
        "the area is read-only (or UM write-protected by the DIP switch)",
        "write to a writable area (DM, W, H, CIO)",
    ),
}
_MODE_REFUSALS = frozenset({0x2201, 0x2202, 0x2203, 0x2204, 0x2205, 0x2206, 0x2207})


class Severity(enum.Enum):
    """How much a finding matters (``aiofins doctor``'s exit code counts problems)."""

    #: As it should be.
    OK = "ok"
    #: Worth knowing; nothing need change for a client to work.
    WARNING = "warning"
    #: Something a client trips over: the finding names the fix.
    PROBLEM = "problem"


@dataclass(frozen=True, slots=True)
class Finding:
    """One finding of :func:`diagnose`: which check, how much it matters, what was found,
    the fix (for a warning or problem) and the values it rests on (``details``)."""

    #: ``udp``, ``tcp``, ``node``, ``reply_port``, ``cpu``, ``memory``, ``writes`` or ``rtt``.
    check: str
    severity: Severity
    summary: str
    fix: str | None = None
    details: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Diagnosis:
    """What :func:`diagnose` found about ``url``.

    ``suggested_url`` is the URL with every fix it can express applied (transport, node,
    local port, SID spaces), or ``None`` if nothing answered; ``reachable`` says whether
    anything answered at all.
    """

    url: str
    findings: tuple[Finding, ...]
    reachable: bool
    suggested_url: str | None

    @property
    def problems(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.severity is Severity.PROBLEM)

    @property
    def exit_code(self) -> int:
        """:data:`EXIT_OK`, :data:`EXIT_PROBLEM` or :data:`EXIT_UNREACHABLE`."""
        if not self.reachable:
            return EXIT_UNREACHABLE
        return EXIT_PROBLEM if self.problems else EXIT_OK

    def as_json(self) -> dict[str, Any]:
        """The ``aiofins doctor --json`` document (docs/cli-json.md)."""
        return {
            "url": self.url,
            "reachable": self.reachable,
            "suggested_url": self.suggested_url,
            "exit_code": self.exit_code,
            "findings": [
                {
                    "check": f.check,
                    "severity": f.severity.value,
                    "summary": f.summary,
                    "fix": f.fix,
                    "details": f.details,
                }
                for f in self.findings
            ],
        }


# -- raw UDP probes ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Reply:
    #: ``"sending"``: to the port the probe left from; ``"fixed"``: to the FINS port here.
    port: str
    frame: ResponseFrame


class _Datagrams:
    """One connected datagram socket, of the operating system or an in-memory network."""

    def __init__(self, send: Callable[[bytes], Any], receive: Any, close: Any) -> None:
        self.send = send
        self.receive = receive
        self.close = close


async def _datagrams(
    remote: tuple[str, int],
    local: tuple[str | None, int],
    network: MemoryNetwork | None,
) -> _Datagrams:
    if network is not None:
        sock = network.datagram_socket(local[0] or network.default_host, local[1], remote=remote)

        async def receive_memory() -> bytes:
            return (await sock.receive())[0]

        return _Datagrams(sock.send, receive_memory, sock.close)
    os_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        os_sock.setblocking(False)
        os_sock.bind((local[0] or "0.0.0.0", local[1]))
        os_sock.connect(remote)
    except BaseException:
        os_sock.close()
        raise

    async def receive_os() -> bytes:
        # A connected socket: an ICMP port unreachable makes it readable and recv() raise.
        while True:
            await anyio.wait_readable(os_sock)
            try:
                return os_sock.recv(4096)
            except (BlockingIOError, InterruptedError):
                continue

    def close_os() -> None:
        os_sock.close()

    return _Datagrams(os_sock.send, receive_os, close_os)


async def _close(sock: _Datagrams) -> None:
    result = sock.close()
    if result is not None:
        await result


async def _send(sock: _Datagrams, frame: bytes) -> None:
    result = sock.send(frame)
    if hasattr(result, "__await__"):
        await result


class _UdpProbe:
    """CPU UNIT STATUS READ sent by hand, from an ephemeral port, with a second socket on
    the FINS port here listening for a reply the PLC sends there instead."""

    def __init__(
        self,
        ip: str,
        port: int,
        local_ip: str | None,
        fixed_ip: str | None,
        timeout: float,
        network: MemoryNetwork | None,
    ) -> None:
        self.ip, self.port, self.local_ip = ip, port, local_ip
        #: Where the second socket listens on the FINS port: our address towards the PLC
        #: (``None``: not at all, the PLC is this computer and holds that port itself).
        self.fixed_ip = fixed_ip
        self.timeout, self.network = timeout, network
        self.sid = 0
        #: Why the fixed port could not be listened on (another program holds it), if so.
        self.fixed_port_busy: str | None = None
        #: The network said nothing listens on the port (ICMP port unreachable).
        self.refused = False

    async def ask(self, dest: int, source: int) -> _Reply | None:
        self.sid = (self.sid + 1) % 256
        sid = self.sid
        frame = build_command(
            FinsAddress(0, dest, 0), FinsAddress(0, source, 0), sid, *_STATUS_READ
        )
        remote = (self.ip, self.port)
        sending = await _datagrams(remote, (self.local_ip, 0), self.network)
        fixed: _Datagrams | None = None
        if self.fixed_ip is not None:
            try:
                fixed = await _datagrams(remote, (self.fixed_ip, self.port), self.network)
            except OSError as exc:
                self.fixed_port_busy = str(exc.strerror or exc)
        found: list[_Reply] = []
        try:
            with anyio.move_on_after(self.timeout) as scope:
                async with anyio.create_task_group() as tg:

                    async def listen(sock: _Datagrams, which: str) -> None:
                        while True:
                            try:
                                data = await sock.receive()
                            except OSError:  # ICMP port unreachable: nobody listens
                                self.refused = True
                                scope.cancel()
                                return
                            except (anyio.ClosedResourceError, anyio.BrokenResourceError):
                                return
                            try:
                                reply = ResponseFrame.decode(data)
                            except (FinsError, ValueError):  # not a FINS response
                                continue
                            if reply.header.sid == sid and reply.command_code == 0x0601:
                                found.append(_Reply(which, reply))
                                scope.cancel()
                                return

                    tg.start_soon(listen, sending, "sending")
                    if fixed is not None:
                        tg.start_soon(listen, fixed, "fixed")
                    await _send(sending, frame)
        finally:
            await _close(sending)
            if fixed is not None:
                await _close(fixed)
        return found[0] if found else None


# -- the diagnosis --------------------------------------------------------------------------


@dataclass
class _Plan:
    """What the probes found works, for the CPU checks and the suggested URL."""

    scheme: str
    node: int | None = None  # DA1 to name in the URL (None: the default is right)
    fixed_port: bool = False
    tcp_node: int | None = None


async def _resolve(host: str, port: int, network: MemoryNetwork | None) -> str:
    if network is not None:
        return host
    try:
        ipaddress.ip_address(host)
    except ValueError:
        infos = await anyio.getaddrinfo(host, port, family=socket.AF_INET, type=socket.SOCK_DGRAM)
        return str(infos[0][4][0])
    return host


def _local_ip(ip: str, port: int) -> str | None:
    """Our address towards ``ip`` (no packet is sent)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect((ip, port))
            return str(probe.getsockname()[0])
    except OSError:
        return None


def _url_node(endpoint: Endpoint) -> int | None:
    node = endpoint.option("node")
    if node is not None:
        return int(option_value("node", node))
    dest = endpoint.option("dest")
    return FinsAddress.parse(dest).node if dest is not None else None


def _url_source(endpoint: Endpoint) -> int | None:
    src = endpoint.option("src")
    return FinsAddress.parse(src).node if src is not None else None


def _suggest(endpoint: Endpoint, plan: _Plan) -> str:
    options = dict(endpoint.options)
    if plan.node is not None and "dest" not in options:
        options["node"] = str(plan.node)
    elif plan.node is not None:
        dest = FinsAddress.parse(options["dest"])
        options["dest"] = str(FinsAddress(dest.network, plan.node, dest.unit))
    if plan.scheme == "udp" and plan.fixed_port:
        options["local_port"] = str(endpoint.port)
        options["max_sid_spaces"] = "1"
    if plan.scheme == "tcp":
        for name in ("local_port",):
            options.pop(name, None)
    host = f"[{endpoint.host}]" if ":" in endpoint.host else endpoint.host
    query = f"?{urlencode(options, safe=',:.')}" if options else ""
    return f"{plan.scheme}://{host}:{endpoint.port}{query}"


async def diagnose(
    url: str,
    *,
    timeout: float = 1.0,
    rounds: int = 5,
    address: str = "D0",
    write_test: bool = False,
    network: MemoryNetwork | None = None,
    local_host: str | None = None,
) -> Diagnosis:
    """Diagnose the connection to the PLC at ``url`` (``udp://`` or ``tcp://``); see the
    module's docstring for the checks. Nothing is written unless ``write_test``.

    Raises :class:`CommandError` for a URL that is not a network one or a bad argument; a
    host name that does not resolve raises :class:`OSError`.
    """
    endpoint = parse_endpoint(url)
    if endpoint.scheme not in ("udp", "tcp"):
        raise CommandError(
            f"aiofins doctor diagnoses udp:// and tcp:// URLs, not {endpoint.scheme}://; "
            "for a serial line see docs/troubleshooting.md"
        )
    if not timeout > 0:
        raise CommandError(f"timeout must be positive seconds, got {timeout!r}")
    if not 1 <= rounds <= 100:
        raise CommandError(f"rounds must be 1..100, got {rounds!r}")
    if ":" in endpoint.host:
        raise CommandError(
            "aiofins doctor diagnoses IPv4 addresses (FINS nodes come from them); "
            f"got {endpoint.host}"
        )
    findings: list[Finding] = []
    ip = await _resolve(endpoint.host, endpoint.port, network)
    port = endpoint.port
    local_ip = local_host if network is not None else None
    if network is not None and local_ip is None:
        local_ip = network.default_host
    our_ip = local_ip if network is not None else _local_ip(ip, port)

    # 1-3: UDP (by hand), then FINS/TCP.
    url_node = _url_node(endpoint)
    ip_node = node_from_host(ip)
    candidates = [n for n in (url_node, ip_node) if n is not None]
    candidates = list(dict.fromkeys(candidates)) or [1]
    our_node = _url_source(endpoint) or (node_from_host(our_ip) if our_ip else None) or 254

    def source_for(dest: int) -> int:
        return our_node if our_node != dest else (254 if dest != 254 else 253)

    fixed_ip = None if our_ip is None or our_ip == ip else our_ip
    probe = _UdpProbe(ip, port, local_ip, fixed_ip, timeout, network)
    udp_reply: _Reply | None = None
    udp_node: int | None = None
    silent: list[int] = []
    for node in candidates:
        udp_reply = await probe.ask(node, source_for(node))
        if udp_reply is not None:
            udp_node = node
            break
        silent.append(node)
    revealed: int | None = None
    if udp_reply is None and not probe.refused:
        udp_reply = await probe.ask(0, source_for(0))
        if udp_reply is not None:
            revealed = udp_reply.frame.header.source.node
            udp_node = revealed
    tcp = await _tcp_probe(ip, port, timeout, network, local_ip)

    # Findings of the transports.
    where = f"{ip}:{port}"
    if udp_reply is not None:
        findings.append(
            Finding(
                "udp",
                Severity.OK,
                f"FINS/UDP answers on {where} (node {udp_node})",
                details={"answers": True, "node": udp_node},
            )
        )
    else:
        why = (
            "nothing listens on that UDP port (ICMP port unreachable)"
            if probe.refused
            else f"no reply to nodes {', '.join(map(str, [*silent, 0]))} within {timeout:g} s"
        )
        findings.append(
            Finding(
                "udp",
                Severity.PROBLEM if endpoint.scheme == "udp" else Severity.WARNING,
                f"FINS/UDP does not answer on {where}: {why}",
                f"use tcp://{endpoint.host}:{port} (FINS/TCP answers)"
                if tcp.answered
                else "check the IP address and port (the Ethernet Unit's FINS UDP port, 9600 "
                "unless set), that the PLC is on and reachable (ping), and no firewall "
                "between",
                details={"answers": False, "refused": probe.refused, "nodes_tried": silent},
            )
        )
    if tcp.answered:
        findings.append(
            Finding(
                "tcp",
                Severity.OK,
                f"FINS/TCP answers on {where} (server node {tcp.server_node}, our node "
                f"{tcp.client_node} from the handshake)",
                details={
                    "answers": True,
                    "server_node": tcp.server_node,
                    "client_node": tcp.client_node,
                },
            )
        )
    else:
        findings.append(
            Finding(
                "tcp",
                Severity.PROBLEM if endpoint.scheme == "tcp" else Severity.WARNING,
                f"FINS/TCP does not answer on {where}: {tcp.why}",
                f"use udp://{endpoint.host}:{port} (FINS/UDP answers)"
                if udp_reply is not None
                else "FINS/TCP needs an Ethernet Unit or built-in port that supports it "
                "(CS1W-ETN21, CJ1W-ETN21, CJ2, NJ/NX ...) with the FINS/TCP server enabled",
                details={"answers": False, "error": tcp.why},
            )
        )

    plan: _Plan | None = None
    if udp_reply is not None and (endpoint.scheme == "udp" or not tcp.answered):
        plan = _Plan("udp", fixed_port=udp_reply.port == "fixed")
    elif tcp.answered:
        plan = _Plan("tcp")

    if plan is not None and plan.scheme == "udp":
        assert udp_node is not None
        findings.extend(_udp_findings(endpoint, plan, udp_node, url_node, revealed, silent))
    elif plan is not None and tcp.server_node is not None:
        findings.append(_tcp_node_finding(plan, tcp.server_node, url_node))
    if probe.fixed_port_busy is not None and udp_reply is None:
        findings.append(
            Finding(
                "reply_port",
                Severity.WARNING,
                f"port {port} could not be listened on here ({probe.fixed_port_busy}): "
                "replies a PLC sends to it (static address conversion) go to the program "
                "holding it",
                "close the other FINS program on this computer (another driver, a "
                "programming tool, a simulator) before using ?local_port=",
                details={"fixed": None, "port": port, "error": probe.fixed_port_busy},
            )
        )

    if plan is None:
        return Diagnosis(url, tuple(findings), False, None)

    # 4-7: the CPU, through the client, as the plan says.
    if plan.scheme == "udp":
        dest_node = udp_node
        transport: UdpTransport | TcpTransport = UdpTransport(
            ip,
            port,
            # bound to the fixed port: on our address towards the PLC, where the probe's
            # second socket got the reply (not every address, which a PLC program on
            # another address of this computer may hold)
            local_host=local_ip if local_ip is not None or not plan.fixed_port else our_ip,
            local_port=port if plan.fixed_port else 0,
            network=network,
        )
        src: FinsAddress | None = FinsAddress(0, source_for(dest_node or 0), 0)
    else:
        dest_node = tcp.server_node
        transport = TcpTransport(
            ip, port, connect_timeout=timeout, network=network, local_host=local_ip
        )
        src = None
    try:
        async with connect(
            transport=transport,
            dest=FinsAddress(0, dest_node or 0, 0),
            src=src,
            timeout=timeout,
            retries=0,
            max_sid_spaces=1,
            read_only=not write_test,
        ) as plc:
            findings.extend(await _cpu_checks(plc, address, write_test, rounds, endpoint))
    except FinsError as exc:
        findings.append(
            Finding(
                "cpu",
                Severity.PROBLEM,
                f"the CPU checks failed: {exc}",
                "run 'aiofins doctor' again; if it persists, see docs/troubleshooting.md",
                details={"error": str(exc)},
            )
        )
    return Diagnosis(url, tuple(findings), True, _suggest(endpoint, plan))


def _udp_findings(
    endpoint: Endpoint,
    plan: _Plan,
    udp_node: int,
    url_node: int | None,
    revealed: int | None,
    silent: list[int],
) -> list[Finding]:
    """The destination node and reply port findings of a PLC that answers FINS/UDP (the
    node to name goes into ``plan``)."""
    out: list[Finding] = []
    port = endpoint.port
    if url_node is not None and udp_node != url_node:
        plan.node = udp_node
        out.append(
            Finding(
                "node",
                Severity.PROBLEM,
                f"node {url_node} (the URL's) is silent; node {udp_node} answers",
                f"set ?node={udp_node} (the PLC's FINS node, its unit number setting)",
                details={"node": udp_node, "url_node": url_node},
            )
        )
    elif revealed is not None:
        plan.node = revealed
        out.append(
            Finding(
                "node",
                Severity.PROBLEM,
                f"node {', '.join(map(str, silent))} is silent; addressed as node 0 (the "
                f"local PLC) it answers as node {revealed}",
                f"set ?node={revealed}, or set the Ethernet Unit's node to the IP "
                "address's last octet (automatic address conversion expects that)",
                details={"node": revealed, "nodes_tried": silent},
            )
        )
    else:
        out.append(
            Finding(
                "node",
                Severity.OK,
                f"destination node {udp_node} ("
                + ("the URL's" if url_node is not None else "the IP address's last octet")
                + ")",
                details={"node": udp_node},
            )
        )
    bound = endpoint.option("local_port") == str(port)
    one_space = endpoint.option("max_sid_spaces") == "1"
    if plan.fixed_port and bound and one_space:
        out.append(
            Finding(
                "reply_port",
                Severity.OK,
                f"replies come to port {port} here (static address conversion or an IP "
                f"address table), which the URL binds with one socket",
                details={"fixed": True, "port": port},
            )
        )
    elif plan.fixed_port:
        out.append(
            Finding(
                "reply_port",
                Severity.PROBLEM,
                f"replies come to port {port} here, not to the port the command left "
                "from: the Ethernet Unit uses static address conversion or an IP address "
                "table (it sends every reply to the FINS port)",
                f"bind that port with one socket: ?local_port={port}&max_sid_spaces=1 "
                "(or set the unit to automatic dynamic conversion)"
                if not bound
                else "add ?max_sid_spaces=1: a second socket could not bind the same port, "
                "and the unit sends all replies to it",
                details={"fixed": True, "port": port},
            )
        )
    else:
        out.append(
            Finding(
                "reply_port",
                Severity.OK,
                "replies come back to the port the command left from (dynamic address conversion)",
                details={"fixed": False},
            )
        )
    return out


def _tcp_node_finding(plan: _Plan, server_node: int, url_node: int | None) -> Finding:
    """The destination node finding over FINS/TCP (the handshake names the server's)."""
    if url_node is None or url_node == server_node:
        return Finding(
            "node",
            Severity.OK,
            f"destination node {server_node} (from the FINS/TCP handshake)",
            details={"node": server_node},
        )
    plan.node = server_node
    return Finding(
        "node",
        Severity.PROBLEM,
        f"the URL names node {url_node}; the FINS/TCP server is node {server_node}",
        f"leave ?node= out on tcp:// (the handshake names it) or set ?node={server_node}",
        details={"node": server_node, "url_node": url_node},
    )


@dataclass
class _TcpResult:
    answered: bool = False
    why: str = ""
    server_node: int | None = None
    client_node: int | None = None


async def _tcp_probe(
    ip: str,
    port: int,
    timeout: float,
    network: MemoryNetwork | None,
    local_ip: str | None,
) -> _TcpResult:
    """FINS/TCP: connect, handshake, CPU UNIT STATUS READ to the handshake's node."""
    result = _TcpResult()
    transport = TcpTransport(
        ip, port, connect_timeout=timeout, network=network, local_host=local_ip
    )
    try:
        with anyio.fail_after(3 * timeout):
            async with connect(transport=transport, timeout=timeout, retries=0) as plc:
                result.server_node = transport.remote_node
                result.client_node = transport.local_node
                await plc.cpu_unit_status_read(timeout=timeout)
                result.answered = True
    except (FinsTimeout, TimeoutError):
        result.why = (
            f"no FINS reply within {timeout:g} s"
            if result.server_node is not None
            else f"no connection or handshake within {timeout:g} s"
        )
    except (FinsError, OSError) as exc:
        result.why = (
            "connection refused (nothing listens on that TCP port)" if _refused(exc) else str(exc)
        )
    return result


def _refused(exc: BaseException) -> bool:
    """Whether a connection refusal is behind ``exc`` (its causes, or the attempts anyio
    made to each address of the host)."""
    seen: list[BaseException] = [exc]
    for error in seen:
        if isinstance(error, ConnectionRefusedError):
            return True
        if len(seen) < 16:
            seen.extend(e for e in (error.__cause__, error.__context__) if e is not None)
            group = getattr(error, "exceptions", ())  # an exception group (Python 3.10 too)
            seen.extend(e for e in group if isinstance(e, BaseException))
    return False


async def _cpu_checks(
    plc: Client, address: str, write_test: bool, rounds: int, endpoint: Endpoint
) -> list[Finding]:
    out: list[Finding] = []
    model: str | None = None
    try:
        data: CpuUnitData = await plc.cpu_unit_data_read()
        model = data.model
    except EndCodeError as exc:
        out.append(
            Finding(
                "cpu",
                Severity.WARNING,
                f"CPU UNIT DATA READ (05 01) refused: end code {exc.code:04X}",
                "the unit answering may not be a CPU Unit (check the node and unit)",
                details={"model": None, "end_code": f"{exc.code:04X}"},
            )
        )
    status: CpuUnitStatus | None = None
    try:
        status = await plc.cpu_unit_status_read()
    except EndCodeError as exc:
        out.append(
            Finding(
                "cpu",
                Severity.WARNING,
                f"CPU UNIT STATUS READ (06 01) refused: end code {exc.code:04X}",
                details={"end_code": f"{exc.code:04X}"},
            )
        )
    mode = status.mode.name if status is not None else None
    if status is not None:
        errors = [str(f.name) for f in type(status.fatal_errors) if f in status.fatal_errors]
        warnings = [
            str(f.name) for f in type(status.non_fatal_errors) if f in status.non_fatal_errors
        ]
        details = {
            "model": model,
            "mode": mode,
            "fatal_errors": errors,
            "non_fatal_errors": warnings,
        }
        text = f"CPU {model or '(model not given)'} in {mode} mode"
        if errors:
            out.append(
                Finding(
                    "cpu",
                    Severity.PROBLEM,
                    f"{text}, fatal error(s): {', '.join(errors)}",
                    "'aiofins status URL' shows the error code and message; clear the cause "
                    "at the PLC",
                    details=details,
                )
            )
        elif status.mode is CpuMode.PROGRAM:
            out.append(
                Finding(
                    "cpu",
                    Severity.WARNING,
                    f"{text}: the program does not run (values do not change; I/O memory "
                    "writes are still accepted)",
                    "switch it to MONITOR or RUN when the program should run ('aiofins run URL')",
                    details=details,
                )
            )
        else:
            extra = f"; non-fatal error(s): {', '.join(warnings)}" if warnings else ""
            out.append(
                Finding(
                    "cpu",
                    Severity.WARNING if warnings else Severity.OK,
                    text + extra,
                    "'aiofins status URL' shows the error" if warnings else None,
                    details=details,
                )
            )
    nj = model is not None and model.strip().upper()[:2] in ("NJ", "NX")
    word: int | None = None
    try:
        word = (await plc.read(address, 1))[0]
    except EndCodeError as exc:
        if nj:
            summary = (
                f"{model} answers {address} with end code {exc.code:04X}: an NJ/NX CPU "
                "answers FINS only for variables AT-mapped to CJ-series memory"
            )
            fix = (
                "in Sysmac Studio, give the variables to read an AT specification (the AT "
                "column, e.g. %D100) or use the 'Memory Settings for CJ-series Units'; read "
                f"those addresses ({address} is not mapped)"
            )
        else:
            summary = f"reading {address} is refused: end code {exc.code:04X} ({exc.end_code.name})"
            fix = "check that the address exists on this CPU (doctor --address ADDRESS)"
        out.append(
            Finding(
                "memory",
                Severity.PROBLEM,
                summary,
                fix,
                details={"address": address, "end_code": f"{exc.code:04X}", "nj_nx": nj},
            )
        )
    else:
        note = " (AT-mapped: NJ/NX answer FINS only there)" if nj else ""
        out.append(
            Finding(
                "memory",
                Severity.OK,
                f"{address} reads{note}",
                details={"address": address, "end_code": "0000", "nj_nx": nj},
            )
        )
    out.append(await _writes(plc, address, word, write_test, mode, endpoint))
    times: list[float] = []
    clock = plc.session.clock  # the session's one clock: the loop's (monotonic under uvloop)
    for _ in range(rounds):
        start = clock()
        await plc.cpu_unit_status_read()
        times.append(clock() - start)
    median = statistics.median(times) * 1000
    out.append(
        Finding(
            "rtt",
            Severity.OK,
            f"round trip {median:.2f} ms (median of {rounds} CPU UNIT STATUS READs)",
            details={"median_ms": round(median, 3), "rounds": rounds},
        )
    )
    return out


async def _writes(
    plc: Client,
    address: str,
    word: int | None,
    write_test: bool,
    mode: str | None,
    endpoint: Endpoint,
) -> Finding:
    text = endpoint.option("read_only")
    read_only = text is not None and switch("read_only", text)
    if write_test and read_only:
        return Finding(
            "writes",
            Severity.WARNING,
            "write test skipped: the URL says read_only",
            "leave ?read_only= out to test writes",
            details={"tested": False, "mode": mode},
        )
    if not write_test:
        summary = (
            "writes not tested (read-only checks; --write-test writes a word's own value back)"
        )
        if read_only:
            summary += "; the URL's read_only refuses writes in the client itself"
        return Finding("writes", Severity.OK, summary, details={"tested": False, "mode": mode})
    if word is None:
        return Finding(
            "writes",
            Severity.WARNING,
            f"write test skipped: {address} could not be read",
            "give a readable word with --address",
            details={"tested": False, "mode": mode},
        )
    try:
        await plc.write(address, [word])
    except EndCodeError as exc:
        code = exc.code
        if code in _WRITE_REFUSALS:
            why, fix = _WRITE_REFUSALS[code]
        elif code in _MODE_REFUSALS:
            why = f"the CPU refuses it in {mode} mode"
            fix = "switch the mode ('aiofins run URL --mode monitor')"
        else:
            why, fix = exc.end_code.name, exc.end_code.correction or "see the end code"
        return Finding(
            "writes",
            Severity.PROBLEM,
            f"writing {address} back is refused: end code {code:04X}, {why}",
            fix,
            details={"tested": True, "refused": True, "end_code": f"{code:04X}", "mode": mode},
        )
    return Finding(
        "writes",
        Severity.OK,
        f"writes accepted ({address} written back with its own value, {word})",
        details={"tested": True, "refused": False, "end_code": "0000", "mode": mode},
    )
