"""``aiofins doctor`` on real loopback sockets against the virtual PLC: the text it prints,
its exit codes (0 no problem, 3 a problem, 4 no answer, 1 an error, 2 bad arguments), and
the arguments of ``aiofins simulate --model/--at`` that set up the NJ case (served by a real
process in tests/simulator/test_cli_simulate.py)."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest
from anyio.from_thread import start_blocking_portal

from aiofins.cli import build_parser, main
from aiofins.simulator import VirtualPLC, run_simulator
from aiofins.simulator.state import Mode


def served(plc: VirtualPLC) -> Iterator[str]:
    with (
        start_blocking_portal() as portal,
        portal.wrap_async_context_manager(
            run_simulator(plc, udp=("127.0.0.1", 0), tcp=("127.0.0.1", 0))
        ) as sim,
    ):
        yield f"udp://127.0.0.1:{sim.udp_port}"


@pytest.fixture
def nj_url() -> Iterator[str]:
    yield from served(VirtualPLC(mode=Mode.RUN, model="NJ501-1300", at_mapped=[("D100", 4)]))


def test_a_healthy_plc_exits_0(url: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["doctor", url, "--rounds", "2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"aiofins doctor {url}"
    assert out[1].startswith("  ok       udp: FINS/UDP answers on 127.0.0.1:")
    assert "  ok       cpu: CPU CJ2M-CPU33 in RUN mode" in out
    assert any(line.startswith("  ok       rtt: round trip ") for line in out)
    assert out[-1] == "no problem found"


def test_an_nj_exits_3_naming_the_at_mapping(
    nj_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["doctor", nj_url, "--timeout", "0.5"]) == 3
    out = capsys.readouterr().out
    assert "  problem  memory: NJ501-1300 answers D0 with end code 1101" in out
    assert "fix: in Sysmac Studio, give the variables to read an AT specification" in out
    assert out.splitlines()[-1] == "1 problem(s) found"
    assert main(["doctor", nj_url, "--address", "D100", "--write-test"]) == 0
    assert "writes accepted (D100 written back with its own value, 0)" in capsys.readouterr().out


def test_nothing_listening_exits_4(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["doctor", f"udp://127.0.0.1:{port}", "--timeout", "0.5"]) == 4
    out = capsys.readouterr().out
    assert "  problem  udp: FINS/UDP does not answer on" in out
    assert out.splitlines()[-1] == "the PLC did not answer"


def test_a_serial_url_is_an_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["doctor", "serial:///dev/ttyUSB0"]) == 1
    assert "diagnoses udp:// and tcp:// URLs" in capsys.readouterr().err


@pytest.mark.parametrize(
    "bad", [["--at", "D0"], ["--at", "D0:x"], ["--at", "Q0:1"], ["--model", "X" * 21]]
)
def test_simulate_refuses_a_bad_model_or_mapping(
    bad: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["simulate", *bad])
    assert exc.value.code == 2
