"""``aiofins.doctor.diagnose`` against the simulator set up each way, on the in-memory
network and virtual time (a silent probe costs no wall-clock time), under trio and asyncio:
the findings, their severities, fixes and details, the exit code and the suggested URL."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pytest

from aiofins.doctor import EXIT_OK, EXIT_PROBLEM, EXIT_UNREACHABLE, Diagnosis, Severity, diagnose
from aiofins.memnet import MemoryNetwork, Packet
from aiofins.protocol.errors import CommandError
from aiofins.protocol.header import FinsAddress
from aiofins.simulator import AddressConversion, EthernetUnit, VirtualPLC, run_simulator
from aiofins.simulator.state import Mode

from .virtual_time import VIRTUAL_BACKENDS, run_on_virtual_time

PLC_IP, OUR_IP = "10.0.0.5", "10.0.0.1"
URL = f"udp://{PLC_IP}"


def run(
    backend: str,
    plc: VirtualPLC | None = None,
    *,
    url: str = URL,
    udp: bool = True,
    tcp: bool = True,
    ethernet: EthernetUnit | None = None,
    latency: float = 0.0,
    fate: Any = None,
    **options: Any,
) -> tuple[Diagnosis, float]:
    """Diagnose ``url`` against ``plc`` served as asked; the diagnosis and the virtual
    seconds it took."""
    out: list[Any] = []

    async def main() -> None:
        import anyio

        served = plc if plc is not None else VirtualPLC(node=5, mode=Mode.RUN)
        async with MemoryNetwork(latency=latency, fate=fate) as net:
            start = anyio.current_time()
            if udp or tcp:
                async with run_simulator(
                    served,
                    udp=(PLC_IP, 9600) if udp else None,
                    tcp=(PLC_IP, 9600) if tcp else None,
                    network=net,
                    ethernet=ethernet,
                ):
                    diagnosis = await diagnose(url, network=net, local_host=OUR_IP, **options)
            else:
                diagnosis = await diagnose(url, network=net, local_host=OUR_IP, **options)
            out.extend([diagnosis, anyio.current_time() - start])

    run_on_virtual_time(main, backend)
    return out[0], out[1]


def by_check(diagnosis: Diagnosis) -> dict[str, list[tuple[Severity, str, str | None]]]:
    found: dict[str, list[tuple[Severity, str, str | None]]] = {}
    for f in diagnosis.findings:
        found.setdefault(f.check, []).append((f.severity, f.summary, f.fix))
    return found


def severities(diagnosis: Diagnosis) -> dict[str, list[str]]:
    return {k: [s.value for s, _, _ in v] for k, v in by_check(diagnosis).items()}


backends = pytest.mark.parametrize("backend", VIRTUAL_BACKENDS)


@backends
def test_a_healthy_plc_is_all_ok_and_the_round_trip_is_the_median_on_the_loop_clock(
    backend: str,
) -> None:
    d, _ = run(backend, latency=0.002, rounds=3)
    assert d.exit_code == EXIT_OK and d.reachable and not d.problems
    assert severities(d) == {
        "udp": ["ok"],
        "tcp": ["ok"],
        "node": ["ok"],
        "reply_port": ["ok"],
        "cpu": ["ok"],
        "memory": ["ok"],
        "writes": ["ok"],
        "rtt": ["ok"],
    }
    rtt = d.findings[-1]
    assert rtt.details == {"median_ms": pytest.approx(4.0), "rounds": 3}  # 2 ms each way
    assert by_check(d)["cpu"][0][1] == "CPU CJ2M-CPU33 in RUN mode"
    assert d.suggested_url == "udp://10.0.0.5:9600"
    document = d.as_json()
    assert document["exit_code"] == 0 and document["findings"][0]["check"] == "udp"


@backends
@pytest.mark.parametrize(
    "unit",
    [
        EthernetUnit(PLC_IP, conversion=AddressConversion.AUTOMATIC_STATIC),
        EthernetUnit(
            PLC_IP, conversion=AddressConversion.IP_ADDRESS_TABLE, node=5, ip_table={1: OUR_IP}
        ),
    ],
    ids=["automatic-static", "ip-table"],
)
def test_replies_to_the_fixed_port_name_local_port_and_one_sid_space(
    backend: str, unit: EthernetUnit
) -> None:
    """The unit sends replies to port 9600 of our address: the probe from an ephemeral port
    gets its reply on the second socket; the CPU checks then run bound to 9600."""
    d, _ = run(backend, ethernet=unit)
    assert d.exit_code == EXIT_PROBLEM
    (problem,) = d.problems
    assert problem.check == "reply_port" and problem.details == {"fixed": True, "port": 9600}
    assert problem.fix is not None and "?local_port=9600&max_sid_spaces=1" in problem.fix
    assert d.suggested_url == "udp://10.0.0.5:9600?local_port=9600&max_sid_spaces=1"
    assert severities(d)["cpu"] == ["ok"] and severities(d)["rtt"] == ["ok"]
    # the URL with the fix applied: all good
    d, _ = run(backend, ethernet=unit, url=str(d.suggested_url))
    assert d.exit_code == EXIT_OK and severities(d)["reply_port"] == ["ok"]
    d, _ = run(backend, ethernet=unit, url=f"{URL}?local_port=9600")
    assert [f.fix for f in d.problems] == [
        "add ?max_sid_spaces=1: a second socket could not bind the same port, and the unit "
        "sends all replies to it"
    ]


@backends
def test_a_node_other_than_the_ip_octet_is_found_by_addressing_node_0(backend: str) -> None:
    d, _ = run(backend, VirtualPLC(node=7, mode=Mode.RUN))
    (problem,) = d.problems
    assert problem.check == "node" and problem.details == {"node": 7, "nodes_tried": [5]}
    assert problem.fix is not None and problem.fix.startswith("set ?node=7")
    assert d.suggested_url == "udp://10.0.0.5:9600?node=7"
    assert severities(d)["cpu"] == ["ok"]


@backends
def test_a_wrong_node_in_the_url_falls_back_to_the_ip_octet(backend: str) -> None:
    d, _ = run(backend, url=f"{URL}?node=9")
    (problem,) = d.problems
    assert problem.check == "node" and problem.details == {"node": 5, "url_node": 9}
    assert d.suggested_url == "udp://10.0.0.5:9600?node=5"


@backends
def test_nothing_listening_is_unreachable_and_told_by_the_network(backend: str) -> None:
    d, elapsed = run(backend, udp=False, tcp=False)
    assert d.exit_code == EXIT_UNREACHABLE and not d.reachable and d.suggested_url is None
    udp, tcp = d.findings
    assert udp.severity is Severity.PROBLEM and udp.details["refused"] is True
    assert "ICMP port unreachable" in udp.summary
    assert tcp.severity is Severity.WARNING and "connection refused" in tcp.summary
    assert elapsed == 0  # refusals are answers: no probe waited for its timeout


@backends
def test_a_silent_network_costs_each_probe_its_timeout(backend: str) -> None:
    def drop(packet: Packet) -> Sequence[float]:
        return []

    d, elapsed = run(backend, fate=drop, timeout=0.5)
    assert d.exit_code == EXIT_UNREACHABLE
    assert "no reply to nodes 5, 0 within 0.5 s" in d.findings[0].summary
    # two UDP probes (node 5, node 0), then the FINS/TCP connect: each bounded
    assert elapsed == pytest.approx(1.5)


@backends
def test_fins_tcp_only(backend: str) -> None:
    d, _ = run(backend, udp=False)
    assert d.exit_code == EXIT_PROBLEM
    (problem,) = d.problems
    assert problem.check == "udp" and problem.fix == "use tcp://10.0.0.5:9600 (FINS/TCP answers)"
    assert d.suggested_url == "tcp://10.0.0.5:9600"
    assert severities(d)["node"] == ["ok"] and severities(d)["cpu"] == ["ok"]
    # and the same PLC named by its tcp:// URL: all good
    d, _ = run(backend, udp=False, url=f"tcp://{PLC_IP}")
    assert d.exit_code == EXIT_OK
    assert severities(d)["udp"] == ["warning"]


@backends
def test_a_wrong_node_on_fins_tcp_is_the_handshake_s(backend: str) -> None:
    d, _ = run(backend, udp=False, url=f"tcp://{PLC_IP}?node=9")
    (problem,) = d.problems
    assert problem.check == "node" and problem.details == {"node": 5, "url_node": 9}
    assert problem.fix == "leave ?node= out on tcp:// (the handshake names it) or set ?node=5"
    assert d.suggested_url == "tcp://10.0.0.5:9600?node=5"


@backends
def test_an_nj_answers_only_at_mapped_memory(backend: str) -> None:
    nj = VirtualPLC(node=5, mode=Mode.RUN, model="NJ501-1300", at_mapped=[("D100", 10)])
    d, _ = run(backend, nj)
    (problem,) = d.problems
    assert problem.check == "memory"
    assert problem.details == {"address": "D0", "end_code": "1101", "nj_nx": True}
    assert "AT-mapped" in problem.summary and "AT specification" in (problem.fix or "")
    d, _ = run(backend, nj, address="D100")
    assert d.exit_code == EXIT_OK
    assert "AT-mapped" in by_check(d)["memory"][0][1]


@backends
def test_read_only_by_default(backend: str) -> None:
    plc = VirtualPLC(node=5, mode=Mode.RUN)
    d, _ = run(backend, plc)
    assert by_check(d)["writes"][0][1].startswith("writes not tested")
    assert plc.write_log == [] and plc.commands[0x0102] == 0


@backends
def test_the_write_test_writes_the_word_back_and_explains_refusals(backend: str) -> None:
    plc = VirtualPLC(node=5, mode=Mode.RUN)
    plc.write("D100", [1234])
    d, _ = run(backend, plc, address="D100", write_test=True)
    assert d.exit_code == EXIT_OK and plc.read("D100") == [1234]
    assert plc.commands[0x0102] == 1
    assert by_check(d)["writes"][0][1] == (
        "writes accepted (D100 written back with its own value, 1234)"
    )

    protected = VirtualPLC(node=5, mode=Mode.PROGRAM, network_write_protection=True)
    d, _ = run(backend, protected, write_test=True)
    assert d.exit_code == EXIT_PROBLEM
    assert severities(d)["cpu"] == ["warning"]  # PROGRAM mode: the program does not run
    (problem,) = d.problems
    assert problem.check == "writes" and problem.details["end_code"] == "2102"
    assert "network write protection" in problem.summary

    held = VirtualPLC(node=5, mode=Mode.RUN)
    held.access_holder = FinsAddress(0, 99, 0)
    d, _ = run(backend, held, write_test=True)
    assert d.exit_code == EXIT_OK  # 5-1-2: I/O memory writes ignore the access right
    d, _ = run(
        backend, VirtualPLC(node=5, mode=Mode.RUN), url=f"{URL}?read_only=1", write_test=True
    )
    assert by_check(d)["writes"][0][0] is Severity.WARNING


def test_only_network_urls_are_diagnosed() -> None:
    async def main() -> None:
        with pytest.raises(CommandError, match="udp:// and tcp://"):
            await diagnose("serial:///dev/ttyUSB0")

    run_on_virtual_time(main, "asyncio")


# -- the operating system's sockets (loopback) ---------------------------------------------


@pytest.mark.anyio
async def test_on_loopback_sockets(anyio_backend: object) -> None:
    """The probes on real sockets, under every event loop: a healthy PLC, then a port
    nobody listens on (the kernel's ICMP port unreachable)."""
    import socket

    async with run_simulator(VirtualPLC(mode=Mode.RUN), udp=("127.0.0.1", 0)) as sim:
        d = await diagnose(f"udp://127.0.0.1:{sim.udp_port}", rounds=2)
    assert d.exit_code == EXIT_OK, d.findings
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    d = await diagnose(f"udp://127.0.0.1:{port}", timeout=5)
    assert d.exit_code == EXIT_UNREACHABLE and d.findings[0].details["refused"] is True
    assert "connection refused" in d.findings[1].summary  # trio: in anyio's attempts


@pytest.mark.anyio
async def test_static_conversion_on_loopback_sockets(anyio_backend: object) -> None:
    """A unit at 127.0.0.2 with static conversion replies to 127.0.0.1 (our node 1) at its
    own FINS port: found on the second socket, and the CPU checks then run bound to it."""
    port = _port_free_on("127.0.0.2", "127.0.0.1")
    unit = EthernetUnit("127.0.0.2", conversion=AddressConversion.AUTOMATIC_STATIC, fins_port=port)
    plc = VirtualPLC(node=2, mode=Mode.RUN)
    async with run_simulator(plc, udp=("127.0.0.2", port), ethernet=unit):
        d = await diagnose(f"udp://127.0.0.2:{port}", rounds=2, timeout=5)
    assert len(d.problems) == 1, d.findings
    (problem,) = d.problems
    assert problem.check == "reply_port" and problem.details == {"fixed": True, "port": port}
    assert d.suggested_url == f"udp://127.0.0.2:{port}?local_port={port}&max_sid_spaces=1"
    assert [f.severity for f in d.findings if f.check in ("cpu", "memory", "rtt")] == [
        Severity.OK
    ] * 3


def _port_free_on(*hosts: str) -> int:
    """A UDP port no socket holds on any of ``hosts`` (other programs on this machine bind
    ports of 127.0.0.1 too: the reply port must be ours alone)."""
    import socket

    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as first:
            first.bind((hosts[0], 0))
            port = int(first.getsockname()[1])
            try:
                for host in hosts[1:]:
                    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
                        other.bind((host, port))
            except OSError:
                continue
            return port
    raise AssertionError(f"no UDP port free on all of {hosts}")
