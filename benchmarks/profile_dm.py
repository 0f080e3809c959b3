"""Where a full DM read's wall time goes on one core: the client's user and system CPU and its
context switches per read, against one 1-word round trip of the same client (issue #25).

Callgrind counts the client's user-space instructions only; on one shared core a big read
also pays system calls (a ``sendto`` and a ``recvmsg`` per frame) and a switch to the C
responder (../shared/tools/perf) whenever a send wakes it. This script reads ``getrusage``
and ``/proc/self/status`` around ``--reads`` reads of ``plc.read_array("D0", 32768)`` (33
frames) and around 100 times as many ``plc.read("D100", 1)``, client and responder pinned
to ``--pin``, for each in-flight cap of ``--caps`` (the session's ``max_in_flight``; 5 is
the default), and prints per read: wall time, user and system CPU, voluntary and
involuntary context switches, and the big read in 1-word round trips.

    python benchmarks/profile_dm.py [--caps 1,5,33] [--reads 100] [--pin 0]
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_session import free_port, start_responder

import aiofins


def sample() -> tuple[float, float, float, int, int]:
    """Wall clock, user and system CPU (s), voluntary and involuntary context switches."""
    use = resource.getrusage(resource.RUSAGE_SELF)
    switches = {}
    with open("/proc/self/status") as status:
        for line in status:
            if "ctxt_switches" in line:
                name, value = line.split(":")
                switches[name] = int(value)
    return (
        time.perf_counter(),
        use.ru_utime,
        use.ru_stime,
        switches["voluntary_ctxt_switches"],
        switches["nonvoluntary_ctxt_switches"],
    )


def per(before: tuple[float, ...], after: tuple[float, ...], n: int) -> list[float]:
    return [(b - a) / n for a, b in zip(before, after, strict=True)]


async def measure(port: int, cap: int, reads: int) -> None:
    url = f"udp://127.0.0.1:{port}?node=1"
    async with aiofins.connect(url, max_in_flight=cap, timeout=2.0) as plc:
        for _ in range(10):
            await plc.read_array("D0", 32768)
            await plc.read("D100", 1)
        before = sample()
        for _ in range(reads):
            await plc.read_array("D0", 32768)
        big = per(before, sample(), reads)
        before = sample()
        for _ in range(100 * reads):
            await plc.read("D100", 1)
        one = per(before, sample(), 100 * reads)
    for name, row in (("full DM read_array", big), ("1-word plc.read", one)):
        wall, user, system, voluntary, involuntary = row
        print(
            f"cap {cap:>3} {name:<19} wall {wall * 1e6:8.1f} us  user {user * 1e6:7.1f} us  "
            f"sys {system * 1e6:7.1f} us  switches {voluntary:5.2f} + {involuntary:5.2f}"
        )
    print(f"cap {cap:>3} full DM in 1-word round trips: {big[0] / one[0]:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--caps", default="1,5,33")
    parser.add_argument("--reads", type=int, default=100)
    parser.add_argument("--pin", type=int, default=0)
    args = parser.parse_args()
    port = free_port()
    responder = start_responder(port, args.pin)
    os.sched_setaffinity(0, {args.pin})
    print(f"load average: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    try:
        for cap in (int(c) for c in args.caps.split(",")):
            anyio.run(measure, port, cap, args.reads, backend_options={"use_uvloop": True})
    finally:
        responder.terminate()
        responder.wait()


if __name__ == "__main__":
    main()
