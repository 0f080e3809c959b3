"""A plant on real Linux networking: virtual PLCs at 192.168.250.N:9600 in network
namespaces on one bridge, ``tc netem`` loss, delay, duplication and reordering on every
link, the client in a namespace of its own (see lab.py; skipped where namespaces cannot be
made). Values, typed errors and counts are asserted — never times.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ..protocol.test_tshark import TSHARK, _warnings, run_tshark
from .lab import REPO, Lab, impairment, unavailable

REASON = unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=REASON or "")

EXAMPLE = REPO / "examples" / "plant.toml"


@pytest.fixture
def lab() -> Iterator[Lab]:
    made = Lab()
    try:
        yield made
    finally:
        made.close()


def one_plc(tmp_path: Path, octet: int, conversion: str = "dynamic") -> Path:
    path = tmp_path / f"plc{octet}.toml"
    table = 'ip_table = { 100 = "192.168.250.100" }' if conversion == "table" else ""
    path.write_text(
        f"""
[[network]]
number = 1
type = "ethernet"

[[plc]]
name = "plc{octet}"
memory = {{ D0 = {[octet * 100 + i for i in range(10)]} }}

[[plc.unit]]
address = 0x10
network = 1
node = {octet}
udp = "192.168.250.{octet}:9600"
conversion = "{conversion}"
{table}
"""
    )
    return path


def serve(lab: Lab, ns: str, plant: Path) -> None:
    lab.start(ns, sys.executable, "-m", "aiofins.cli", "simulate", "--plant", str(plant),
              ready="listening on")  # fmt: skip


def check_route(lab: Lab, client: str, octet: int) -> None:
    """The client's namespace has a route to the PLC (and only through the lab's link)."""
    route = lab.exec(client, "ip", "route", "get", f"192.168.250.{octet}").stdout
    assert f"dev {lab.device(100)}" in route, route


def workload(
    lab: Lab, client: str, backend: str, scenario: str, *extra: str
) -> dict[str, dict[str, Any]]:
    done = lab.exec(client, sys.executable, "-m", "tests.netns.workload", backend, scenario, *extra)
    result: dict[str, dict[str, Any]] = json.loads(done.stdout)
    return result


def assert_counted(counts: dict[str, Any], calls: int, *, errors: set[str]) -> None:
    """0 wrong values; every call either exact values or a typed error of ``errors``."""
    assert counts.get("wrong", 0) == 0, counts
    failures = {k: v for k, v in counts.items() if k not in ("ok", "wrong", "source_node", "stats")}
    assert set(failures) <= errors, counts
    assert counts.get("ok", 0) + sum(failures.values()) == calls, counts


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_udp_plcs_by_ip_address_with_netem_faults(lab: Lab, tmp_path: Path, backend: str) -> None:
    client = lab.host("client", 100)
    serve(lab, lab.host("plc3", 3), one_plc(tmp_path, 3))
    serve(lab, lab.host("plc4", 4), one_plc(tmp_path, 4, "table"))
    gateway = tmp_path / "plant.toml"
    gateway.write_text(EXAMPLE.read_text().replace("127.0.0.10:9600", "192.168.250.10:9600"))
    serve(lab, lab.host("line", 10), gateway)
    for octet in (3, 4, 10):
        check_route(lab, client, octet)
    capture = tmp_path / "client.pcapng"
    dumpcap = lab.capture(client, lab.device(100), capture) if TSHARK else None
    result = workload(lab, client, backend, "udp_plant")
    if dumpcap is not None:  # Wireshark's dissector reads every frame on the client's link
        lab.stop(dumpcap)
        rows = run_tshark(capture, "udp.port==9600,omron")
        assert len(rows) >= 600, len(rows)  # 300 reads and their replies, at least
        for row in rows:
            assert row["omron.command"] == "0x0101", row  # MEMORY AREA READ
            assert row["_ws.malformed"] == "" and not _warnings(row), row
    for name in ("dynamic", "ip_table", "routed"):
        assert_counted(result[name], 100, errors={"FinsTimeout"})
        assert result[name]["ok"] >= 50, result  # 3 retries: almost every call succeeds
        assert result[name]["source_node"] == 100  # our node: the last octet of our address
    # The links really lose frames (10 % each way over ~600 datagrams): the session resent.
    assert sum(result[n]["stats"]["retries"] for n in ("dynamic", "ip_table", "routed")) > 0
    print(f"links impaired by {impairment()}: {json.dumps(result)}")
    # The IP address table answers to port 9600: a client on another port hears nothing.
    assert result["ip_table_without_local_port"] == {"FinsTimeout": 3}


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_fins_tcp_through_a_link_that_drops(lab: Lab, backend: str) -> None:
    client = lab.host("client", 100)
    plc = lab.host("plc5", 5)
    lab.start(plc, sys.executable, "-m", "aiofins.cli", "simulate", "--tcp",
              "192.168.250.5:9600", "--node", "5", ready="listening on")  # fmt: skip
    check_route(lab, client, 5)
    result = workload(lab, client, backend, "tcp_link_drops", lab.device(100))
    assert_counted(result["lossy"], 50, errors={"FinsTimeout", "ConnectionLost"})
    assert result["lossy"]["ok"] >= 40, result  # TCP retransmits what the link drops
    assert_counted(result["down"], 3, errors={"FinsTimeout", "ConnectionLost"})
    assert result["down"].get("ok", 0) == 0
    up = result["up_again"]  # until the first success (at most 60 calls), then 10 more
    calls = up.get("ok", 0) + up.get("FinsTimeout", 0) + up.get("ConnectionLost", 0)
    assert_counted(up, calls, errors={"FinsTimeout", "ConnectionLost"})
    assert up.get("ok", 0) >= 1, result  # the session reconnected by itself
