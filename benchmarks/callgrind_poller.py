"""Instructions per scan of the Poller, counted by callgrind (not timed).

A :class:`~aiofins.Poller` (through a :class:`~aiofins.Pool`; stock asyncio, or uvloop with
``--loop uvloop``) scans ``--plcs`` PLCs on loopback UDP, each with ``bench_api.py``'s
20-tag, one-frame group, every ``--interval`` seconds, and a consumer takes the snapshots.
The run is made twice under ``valgrind --tool=callgrind``, ending after 100 and after 600
snapshots; the difference divided by 500 is the marginal cost of one scan (timer, lease,
request, reply, decode, snapshot, channel, consumer), free of start-up, imports and the
sessions' opening.

The PLCs are virtual PLCs (``aiofins simulate``, separate processes: their work is not
counted) that answer ``--delay`` ms after each request (default 10, under the 20 ms floor
of the retransmission timeout), as a PLC across a network does: the reply comes once the
poller's event loop waits for it. One PLC by default: with several, how many replies one
event-loop pass finds varies from run to run, and the count with it. (The C responder
answers within microseconds, while the poller under valgrind runs ~50 times slower: every
reply would be in the socket before the poller looked, which no real scan sees.)
``--delay 0`` uses the C responders of ../shared/tools/perf instead.

Usage (valgrind must be installed)::

    python benchmarks/callgrind_poller.py                    # this tree
    python benchmarks/callgrind_poller.py --src ../old/src   # another tree

``--inner N PORTS INTERVAL LOOP`` runs one workload without valgrind (what the outer run starts).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

SMALL, LARGE = 100, 600
SIMULATE = (sys.executable, "-m", "aiofins", "simulate")


def _workload(n: int, ports: list[int], interval: float, loop: str = "asyncio") -> None:
    from bench_api import TAGS

    from aiofins.poller import Poller
    from aiofins.pool import Pool

    async def main() -> None:
        async with (
            Pool(timeout=2.0, max_sessions=len(ports) + 16) as pool,
            Poller(pool, buffer=4096) as poller,
        ):
            for port in ports:
                url = f"udp://127.0.0.1:{port}?node=1"
                poller.add_group(str(port), url, TAGS, interval=interval)
            seen = 0
            async for snap in poller:
                if snap.error is not None:
                    raise AssertionError(snap.error)
                seen += 1
                if seen >= n:
                    break

    if loop == "uvloop":
        import uvloop

        uvloop.install()
    asyncio.run(main())


async def _answering(ports: list[int]) -> None:
    """Wait until every PLC answers (they take a while to start on a busy machine)."""
    import aiofins

    logging.getLogger("aiofins").setLevel(logging.ERROR)  # (the probes' timeouts)
    deadline = time.monotonic() + 60
    for port in ports:
        while True:
            try:
                async with aiofins.connect(f"udp://127.0.0.1:{port}?node=1", timeout=0.5) as plc:
                    await plc.read("D0", 1)
                break
            except aiofins.FinsError:
                if time.monotonic() > deadline:
                    raise


@contextmanager
def simulators(count: int, delay: int) -> Iterator[list[int]]:
    """``count`` virtual PLCs answering ``delay`` ms after each request; their ports."""
    from bench_session import free_ports

    ports = free_ports(count)
    procs = [
        subprocess.Popen(
            [*SIMULATE, "--udp", f"127.0.0.1:{p}", "--node", "1", "--delay", str(delay)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for p in ports
    ]
    try:
        asyncio.run(_answering(ports))
        yield ports
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.wait()


def _instructions(n: int, ports: list[int], interval: float, src: str | None, loop: str) -> int:
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = os.path.abspath(src)
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "callgrind.out")
        command = [
            "valgrind",
            "--tool=callgrind",
            f"--callgrind-out-file={out}",
            sys.executable,
            __file__,
            "--inner",
            str(n),
            ",".join(map(str, ports)),
            str(interval),
            loop,
        ]
        subprocess.run(command, check=True, env=env, capture_output=True, text=True)
        with open(out) as f:
            text = f.read()
    match = re.search(r"^(?:summary|totals): (\d+)", text, re.MULTILINE)
    assert match, "no totals in callgrind's output"
    return int(match.group(1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--src", help="the src/ directory of the tree to measure")
    parser.add_argument("--plcs", type=int, default=1, help="PLCs (default 1)")
    parser.add_argument("--interval", type=float, default=0.05, help="seconds between scans")
    parser.add_argument("--loop", default="asyncio", choices=("asyncio", "uvloop"))
    parser.add_argument("--delay", type=int, default=10, help="ms before each reply (0: C)")
    parser.add_argument(
        "--inner", nargs=4, metavar=("N", "PORTS", "INTERVAL", "LOOP"), help=argparse.SUPPRESS
    )
    args = parser.parse_args()
    if args.inner:
        n, ports, interval, loop = args.inner
        _workload(int(n), [int(p) for p in ports.split(",")], float(interval), loop)
        return
    from bench_api import responders

    peers = simulators(args.plcs, args.delay) if args.delay else responders(args.plcs)
    with peers as ports:
        small = _instructions(SMALL, ports, args.interval, args.src, args.loop)
        large = _instructions(LARGE, ports, args.interval, args.src, args.loop)
    per = (large - small) / (LARGE - SMALL)
    print(
        f"poller   {per / 1000:8.1f}k instructions per scan ({args.plcs} PLCs, "
        f"replies after {args.delay} ms, {args.loop})",
        flush=True,
    )


if __name__ == "__main__":
    main()
