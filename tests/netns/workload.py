"""The client side of the namespace tests, run inside the client's namespace:
``python -m tests.netns.workload BACKEND SCENARIO``. Prints one JSON document of counts.

Every call's outcome is counted: ``ok`` (the exact values expected), ``wrong`` (other
values: must stay 0), or the name of the typed :class:`aiofins.FinsError` it raised. Any
other exception ends the run with a traceback (the test fails).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from typing import Any

import anyio

import aiofins

ROUNDS = 100
#: FINS/TCP calls over the lossy link (a lost segment costs TCP's 200 ms retransmission).
TCP_ROUNDS = 50


async def _count(
    plc: aiofins.Client, counts: Counter[str], expected: list[int], rounds: int, **kw: Any
) -> None:
    for _ in range(rounds):
        try:
            values = await plc.read("D0", len(expected), **kw)
        except aiofins.FinsError as exc:
            counts[type(exc).__name__] += 1
            continue
        counts["ok" if values == expected else "wrong"] += 1


async def udp_plant() -> dict[str, dict[str, Any]]:
    """Three PLCs of a plant, by IP address: dynamic conversion (.3), an IP address table
    answering to port 9600 only (.4; without local_port nothing comes back), and a
    gateway (.10) to a PLC two networks away."""
    out: dict[str, dict[str, Any]] = {}
    targets: dict[str, tuple[str, dict[str, Any], list[int]]] = {
        "dynamic": ("udp://192.168.250.3", {}, [300 + i for i in range(10)]),
        "ip_table": (
            "udp://192.168.250.4?local_port=9600",
            {"max_sid_spaces": 1},
            [400 + i for i in range(10)],
        ),
        "routed": (
            "udp://192.168.250.10?source_network=1&routes=2:controller_link,3:sysmac_link",
            {"dest": "3.5.0"},
            [1234, 5678],
        ),
    }
    for name, (url, options, expected) in targets.items():
        counts: Counter[str] = Counter()
        async with aiofins.connect(url, timeout=1.0, retries=3, **options) as plc:
            await _count(plc, counts, expected, ROUNDS)
            out[name] = dict(counts)
            out[name]["source_node"] = plc.session.source.node
            stats = plc.session.stats
            out[name]["stats"] = {
                "retries": stats.retries,
                "duplicates": stats.duplicates,
                "late_replies": stats.late_replies,
                "timeouts": stats.timeouts,
            }
    counts = Counter()
    async with aiofins.connect("udp://192.168.250.4", timeout=0.2, retries=0) as plc:
        await _count(plc, counts, [400 + i for i in range(10)], 3)
    out["ip_table_without_local_port"] = dict(counts)
    return out


async def tcp_link_drops() -> dict[str, dict[str, int]]:
    """FINS/TCP to .5 (netem loss on the link), then the client's link goes down (every
    call fails, typed), then up again (calls succeed again)."""
    device = sys.argv[3]
    # The set-up connection is not what is counted: over the lossy link the handshake can
    # outlast the simulator's 2 s handshake deadline (it then closes the connection), so a
    # few attempts, bounded by count.
    for attempt in range(1, 6):
        entered = False
        try:
            # No circuit breaker (it would fail calls at once while it waits to probe: this
            # test counts calls until the link is back), quick reconnection attempts.
            async with aiofins.connect(
                "tcp://192.168.250.5",
                timeout=2.0,
                retries=2,
                breaker_threshold=0,
                reconnect_backoff=(0.05, 0.5),
            ) as plc:
                entered = True
                return await _tcp_scenario(plc, device)
        except aiofins.ConnectionLost:
            if entered or attempt == 5:
                raise
    raise AssertionError("unreachable")


async def _tcp_scenario(plc: aiofins.Client, device: str) -> dict[str, dict[str, int]]:
    out: dict[str, dict[str, int]] = {}
    # The set-up write is not what is counted: a generous deadline, so that a few lost
    # segments in a row (TCP's retransmissions back off: 0.2, 0.4, 0.8 s, ...) on a
    # busy machine cannot fail the scenario before it starts.
    await plc.write("D0", list(range(500, 510)), timeout=20.0)
    expected = list(range(500, 510))
    counts: Counter[str] = Counter()
    await _count(plc, counts, expected, TCP_ROUNDS)
    out["lossy"] = dict(counts)
    subprocess.run(["ip", "link", "set", device, "down"], check=True)
    counts = Counter()
    await _count(plc, counts, expected, 3, timeout=0.5)
    out["down"] = dict(counts)
    subprocess.run(["ip", "link", "set", device, "up"], check=True)
    counts = Counter()
    for _ in range(60):  # until the session has reconnected: bounded by count, not time
        await _count(plc, counts, expected, 1)
        if counts["ok"]:
            break
    await _count(plc, counts, expected, 10)
    out["up_again"] = dict(counts)
    return out


SCENARIOS = {"udp_plant": udp_plant, "tcp_link_drops": tcp_link_drops}


def main() -> None:
    backend, scenario = sys.argv[1], sys.argv[2]
    result = anyio.run(SCENARIOS[scenario], backend=backend)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
