"""``aiofins simulate``: a real process serving loopback UDP/TCP, stopped by SIGINT/SIGTERM."""

from __future__ import annotations

import argparse
import re
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator

import pytest

from aiofins.cli import build_parser, main
from aiofins.cli.simulate import build_plan, endpoint, endpoints
from aiofins.simulator import Delay, FaultRule

from .test_servers import READ_D100, node_response

TIMEOUT = 10


class SimulatorProcess:
    def __init__(self, *options: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "aiofins.cli", "simulate", *options],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.urls: dict[str, tuple[str, int]] = {}
        self.banner = ""

    def wait_listening(self, count: int) -> None:
        assert self.proc.stdout is not None
        while len(self.urls) < count:
            line = self.proc.stdout.readline()
            if not line:
                pytest.fail(f"simulator exited: {self.stop()}")
            if line.startswith("virtual PLC"):
                self.banner = line.strip()
            match = re.fullmatch(r"listening on (udp|tcp)://([\d.]+):(\d+)\n", line)
            if match:
                self.urls[match.group(1)] = (match.group(2), int(match.group(3)))

    def stop(self, sig: int = signal.SIGINT) -> tuple[int, str]:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        _, err = self.proc.communicate(timeout=TIMEOUT)
        return self.proc.returncode, err


@pytest.fixture
def process_factory() -> Iterator[list[SimulatorProcess]]:
    started: list[SimulatorProcess] = []
    yield started
    for p in started:
        if p.proc.poll() is None:
            p.proc.kill()
            p.proc.communicate(timeout=TIMEOUT)


def start(started: list[SimulatorProcess], *options: str, endpoints: int) -> SimulatorProcess:
    p = SimulatorProcess(*options)
    started.append(p)
    p.wait_listening(endpoints)
    return p


def udp_exchange(address: tuple[str, int], frame: bytes) -> bytes:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(TIMEOUT)
        sock.sendto(frame, address)
        return sock.recv(4096)


def test_serves_udp_and_tcp_and_stops_on_sigint(process_factory: list[SimulatorProcess]) -> None:
    sim = start(
        process_factory,
        "--udp", "127.0.0.1:0", "--tcp", "127.0.0.1:0", "--node", "10", "--mode", "monitor",
        endpoints=2,
    )  # fmt: skip
    assert sim.banner == "virtual PLC: network 0 node 10 mode MONITOR"
    reply = udp_exchange(sim.urls["udp"], READ_D100)
    assert reply[:14] == bytes.fromhex("C0 00 02 00 22 00 00 0A 00 01 01 01 00 00")
    assert len(reply) == 14 + 20
    with socket.create_connection(sim.urls["tcp"], timeout=TIMEOUT) as conn:
        conn.sendall(bytes.fromhex("46494E53 0000000C 00000000 00000000 00000000"))
        assert conn.recv(24) == node_response(0xEF, 10)
    code, err = sim.stop(signal.SIGINT)
    assert code == 0
    assert "stopped: requests=1 responses=1" in err


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_faults_from_the_command_line(
    process_factory: list[SimulatorProcess], backend: str
) -> None:
    sim = start(
        process_factory,
        "--udp", "127.0.0.1:0", "--node", "10", "--end-code", "1103", "--flags", "40",
        "--commands", "0101", "--seed", "5", "--backend", backend,
        endpoints=1,
    )  # fmt: skip
    reply = udp_exchange(sim.urls["udp"], READ_D100)
    assert reply == bytes.fromhex("C0 00 02 00 22 00 00 0A 00 01 01 01 11 43")
    code, err = sim.stop(signal.SIGTERM)
    assert code == 0
    assert "end_codes=1 flags=1" in err


def test_tcp_refusal_option(process_factory: list[SimulatorProcess]) -> None:
    sim = start(process_factory, "--tcp", "127.0.0.1:0", "--tcp-refuse", "25", endpoints=1)
    with socket.create_connection(sim.urls["tcp"], timeout=TIMEOUT) as conn:
        conn.sendall(bytes.fromhex("46494E53 0000000C 00000000 00000000 00000005"))
        assert conn.recv(24) == node_response(5, 1, 0x25)
    assert sim.stop()[0] == 0


@pytest.mark.parametrize(
    ("bad", "said"),
    [
        (["--node", "0"], "argument --node: 0 out of range 1..254"),
        (["--node", "x"], "argument --node: 'x' is not an integer"),
        (["--network", "128"], "argument --network: 128 out of range 0..127"),
        (["--serial-unit", "32"], "argument --serial-unit: 32 out of range 0..31"),
        (["--baudrate", "0"], "argument --baudrate: 0 out of range at least 1"),
        (["--max-connections", "0"], "argument --max-connections: 0 out of range at least 1"),
        (["--max-concurrent", "-1"], "argument --max-concurrent: -1 out of range at least 1"),
        (["--max-held", "0"], "argument --max-held: 0 out of range at least 1"),
        (["--late-after", "nan"], "argument --late-after: nan ms: give a finite number"),
        (["--late-after", "inf"], "argument --late-after: inf ms: give a finite number"),
        (["--late-after=-5"], "argument --late-after: -5 ms: give a finite number"),
        (["--delay", "nan"], "argument --delay: delay range nan..nan is not finite"),
        (["--delay", "inf"], "argument --delay: delay range inf..inf is not finite"),
        (["--delay=-5"], "argument --delay: delay '-5' is not MS or MIN-MAX"),
        (["--delay", "9-1"], "argument --delay: delay range 0.009..0.001 is not 0 <= min"),
        (["--drop", "2"], "argument --drop: probability 2 out of range 0..1"),
        (["--late", "nan"], "argument --late: probability nan out of range 0..1"),
        (["--corrupt=-0.1"], "argument --corrupt: probability -0.1 out of range 0..1"),
        (["--udp", "host:port"], "argument --udp: 'host:port' is not HOST:PORT"),
        (["--mode", "x"], "argument --mode: invalid choice: 'x'"),
    ],
)
def test_bad_options_exit_2(capsys: pytest.CaptureFixture[str], bad: list[str], said: str) -> None:
    """--max-connections 0 ended in a traceback; --late-after nan was accepted."""
    with pytest.raises(SystemExit) as info:
        main(["simulate", "--udp", "127.0.0.1:0", *bad])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("bad", "said"),
    [
        (["--end-code", "10000"], "end code 0x10000 out of range 0..0xFFFF"),
        (["--flags", "41"], "flags 0x41 may only combine 0x40 and 0x80"),
        (["--relay", "300.1", "--end-code", "8101"], "relay point (300, 1) out of range"),
        (["--tcp-refuse", "0"], "FINS/TCP refusal code 0x0 must be non-zero u32"),
    ],
)
def test_bad_fault_settings_exit_2(
    capsys: pytest.CaptureFixture[str], bad: list[str], said: str
) -> None:
    assert main(["simulate", "--udp", "127.0.0.1:0", *bad]) == 2
    err = capsys.readouterr().err
    assert f"aiofins simulate: {said}" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:0", ("127.0.0.1", 0)),
        ("0.0.0.0:9600", ("0.0.0.0", 9600)),
        ("localhost", ("localhost", 9600)),
        (":9601", ("127.0.0.1", 9601)),
        ("[::1]:9602", ("::1", 9602)),
        ("::1", ("::1", 9600)),
    ],
)
def test_endpoint(text: str, expected: tuple[str, int]) -> None:
    assert endpoint(text) == expected


def parse(*options: str) -> argparse.Namespace:
    return build_parser().parse_args(["simulate", *options])


def test_build_plan_default_and_per_command() -> None:
    plan = build_plan(
        parse("--drop", "0.5", "--delay", "10-20", "--seed", "3", "--max-concurrent", "4")
    )
    assert plan.rule == FaultRule(drop_request=0.5, delay=Delay(0.01, 0.02))
    assert plan.seed == 3
    assert plan.max_concurrent == 4
    assert plan.per_command == {}
    plan = build_plan(parse("--duplicate", "1", "--commands", "0101,0102", "--relay", "1.5"))
    assert plan.rule == FaultRule()
    expected = FaultRule(duplicate=1.0, relay=(1, 5))
    assert plan.per_command == {0x0101: expected, 0x0102: expected}
    plan = build_plan(parse("--late", "0.2", "--late-after", "500"))
    assert plan.rule == FaultRule(late=0.2, late_after=0.5)


def test_no_fault_option_means_the_fast_path() -> None:
    """Without fault options the UDP server answers each datagram at once (no task each):
    the rule simulate builds must equal 'no fault' (late_after was always set)."""
    from aiofins.simulator.faults import Dispatcher
    from aiofins.simulator.plc import VirtualPLC

    assert Dispatcher(VirtualPLC(), build_plan(parse())).quiet
    assert not Dispatcher(VirtualPLC(), build_plan(parse("--late", "0.1"))).quiet


def test_a_broken_subcommand_module_fails_loudly(monkeypatch: pytest.MonkeyPatch) -> None:
    import aiofins.cli as cli

    monkeypatch.setattr(cli, "SUBCOMMANDS", ("no_such_module", "simulate"))
    with pytest.raises(ModuleNotFoundError, match="no_such_module"):
        main(["simulate", "--node", "3"])


def test_default_endpoints() -> None:
    default = ("127.0.0.1", 9600)
    assert endpoints(parse()) == (default, default)
    assert endpoints(parse("--tcp", "0.0.0.0:9601")) == (None, ("0.0.0.0", 9601))
    assert endpoints(parse("--serial", "/dev/ttyUSB0")) == (None, None)


def test_an_nj_model_answers_only_its_at_mapped_memory(
    process_factory: list[SimulatorProcess], capsys: pytest.CaptureFixture[str]
) -> None:
    """``--model NJ501-1300 --at D100:10``: D100..D109 read, D0 answers 1101 (area
    missing), and ``aiofins doctor`` names the AT mapping (exit 3)."""
    sim = start(
        process_factory, "--udp", "127.0.0.1:0", "--node", "10", "--model", "NJ501-1300",
        "--at", "D100:10", endpoints=1,
    )  # fmt: skip
    reply = udp_exchange(sim.urls["udp"], READ_D100)  # D100, 10 words
    assert reply[12:14] == b"\x00\x00" and len(reply) == 14 + 20
    read_d0 = READ_D100[:-6] + bytes.fromhex("82 0000 00 000A")
    assert udp_exchange(sim.urls["udp"], read_d0) == reply[:12] + b"\x11\x01"
    host, port = sim.urls["udp"]
    assert main(["doctor", f"udp://{host}:{port}?node=10", "--timeout", "2"]) == 3
    assert "NJ501-1300 answers D0 with end code 1101" in capsys.readouterr().out
    code, _ = sim.stop(signal.SIGTERM)
    assert code == 0
