"""``aiofins.sync`` against PyPI ``fins``: sequential one-word reads, interleaved rounds.

Each round runs every case once, one after another, against the C responder of
../shared/tools/perf (word i of its DM holds i), and takes each ratio within the round; the
table gives the median over the rounds and the range (min-max). Cases:

* ``fins``: PyPI ``fins``' UDP ``memory_area_read`` of D100 and the word decoded;
* ``sync``: ``aiofins.sync.connect("udp://...")``'s ``plc.read("D100", 1)``: the calling
  thread drives the session on a blocking socket;
* ``sync-tcp``: the same over FINS/TCP;
* ``sync-loop``: ``aiofins.sync.connect(url, backend="asyncio")``: each call sent to the
  private loop's thread (the mode for concurrent calls from several threads).

    python benchmarks/bench_sync.py [--rounds 5] [--seconds 1] [--pin 0 | --pin 0,1]

``--pin 0`` puts the responder and the client on core 0 (issue #25's one-core row);
``--pin 0,1`` gives each a core. Wall clock: read the ratios, and the load average printed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_session import free_port, start_responder
from bench_targets import pypi_fins_sequential, rate

import aiofins.sync


def sync_sequential(url: str, seconds: float, backend: str | None = None) -> float:
    """Reads per second of ``plc.read("D100", 1)`` one after another."""
    with aiofins.sync.connect(url, backend=backend) as plc:
        read = plc.read
        assert read("D100", 1) == [100]
        return rate(seconds, lambda: read("D100", 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--pin", default="0", help="responder core[,client core]")
    args = parser.parse_args()
    cores = [int(c) for c in args.pin.split(",") if c.strip()]
    responder_core = cores[0] if cores else None
    client_core = cores[-1] if cores else None
    if client_core is not None:
        os.sched_setaffinity(0, {client_core})
    port = free_port()
    responder = start_responder(port, responder_core)
    rows: dict[str, list[float]] = {}
    try:
        print(f"load average before: {os.getloadavg()}")
        for n in range(args.rounds):
            peer = pypi_fins_sequential(port, args.seconds)
            udp = sync_sequential(f"udp://127.0.0.1:{port}?node=1", args.seconds)
            tcp = sync_sequential(f"tcp://127.0.0.1:{port}", args.seconds)
            loop = sync_sequential(f"udp://127.0.0.1:{port}?node=1", args.seconds, "asyncio")
            for name, value in (
                ("PyPI fins (k/s)", peer / 1e3),
                ("aiofins.sync UDP (k/s)", udp / 1e3),
                ("aiofins.sync FINS/TCP (k/s)", tcp / 1e3),
                ("aiofins.sync backend=asyncio (k/s)", loop / 1e3),
                ("aiofins.sync UDP / PyPI fins", udp / peer),
                ("aiofins.sync FINS/TCP / PyPI fins", tcp / peer),
                ("backend=asyncio / PyPI fins", loop / peer),
            ):
                rows.setdefault(name, []).append(value)
            print(f"round {n + 1}: sync/fins {udp / peer:.2f}", flush=True)
        print(f"load average after: {os.getloadavg()}")
    finally:
        responder.kill()
        responder.wait()
    where = "one core" if len(set(cores)) == 1 else "a core each"
    print(f"\n{args.rounds} rounds x {args.seconds} s, responder and client on {where}")
    print(f"{'row':40} {'median':>8}  range")
    for name, values in rows.items():
        print(f"{name:40} {statistics.median(values):8.2f}  {min(values):.2f}-{max(values):.2f}")


if __name__ == "__main__":
    main()
