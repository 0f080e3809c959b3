"""Python opcodes per Poller scan, by function (``sys.settrace`` opcode events; not timed).

A Poller (uvloop) scans ``--plcs`` C responders (../shared/tools/perf) with ``bench_api.py``'s
20-tag, one-frame group every 50 ms; after 200 snapshots the next ``--scans`` are traced and
every Python function's opcodes (and calls) are divided by the scans: the profile by
component behind the Poller's row in benchmarks/README.md. C code (the event loop, ``struct``,
the socket) is not counted: ``callgrind_poller.py`` counts instructions.

    python benchmarks/opcodes_poller.py [--plcs 10] [--scans 1000] [--top 40] [--interval 0.05]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections import Counter
from pathlib import Path
from types import FrameType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

WARM_UP = 200


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plcs", type=int, default=10)
    parser.add_argument("--scans", type=int, default=1000)
    parser.add_argument("--top", type=int, default=40)
    parser.add_argument(
        "--interval",
        type=float,
        default=0.05,
        help="seconds between scans (longer on a busy machine: no missed scans)",
    )
    args = parser.parse_args()

    import uvloop
    from bench_api import TAGS, responders

    from aiofins.poller import Poller
    from aiofins.pool import Pool

    opcodes: Counter[str] = Counter()
    calls: Counter[str] = Counter()

    def tracer(frame: FrameType, event: str, arg: Any) -> Any:
        frame.f_trace_opcodes = True
        code = frame.f_code
        key = f"{code.co_filename.split('/src/')[-1]}:{code.co_firstlineno}:{code.co_name}"
        calls[key] += event == "call"

        def local(frame: FrameType, event: str, arg: Any) -> Any:
            if event == "opcode":
                opcodes[key] += 1
            return local

        return local

    missed = [0]  # scans missed while traced (their warnings add opcodes)

    async def run(ports: list[int]) -> None:
        async with (
            Pool(timeout=2.0, max_sessions=len(ports) + 16) as pool,
            Poller(pool, buffer=4096) as poller,
        ):
            for port in ports:
                url = f"udp://127.0.0.1:{port}?node=1"
                poller.add_group(str(port), url, TAGS, interval=args.interval)
            seen = 0
            async for _ in poller:
                seen += 1
                if seen == WARM_UP:
                    missed[0] = -sum(g.missed for g in poller.groups.values())
                    sys.settrace(tracer)
                if seen == WARM_UP + args.scans:
                    sys.settrace(None)
                    missed[0] += sum(g.missed for g in poller.groups.values())
                    break

    with responders(args.plcs) as ports:
        uvloop.install()
        asyncio.run(run(ports))
    print(
        f"opcodes per scan: {sum(opcodes.values()) / args.scans:.0f}  (calls per scan; "
        f"{missed[0]} scans missed while traced)"
    )
    for key, n in opcodes.most_common(args.top):
        print(f"{n / args.scans:8.1f}  ({calls[key] / args.scans:4.2f})  {key}")


if __name__ == "__main__":
    main()
