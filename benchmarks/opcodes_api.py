"""Python opcodes per operation of the async client, by function: sequential ``plc.read``, 50
tasks x ``plc.read`` on one client, and a full DM read by ``read_array`` (per frame).

``sys.settrace`` opcode events, not timed (uvloop, against the C responder of
../shared/tools/perf). After 20 untimed operations the next ``--ops`` are traced and each
Python function's opcodes (and calls: a coroutine's resumption counts as one) are divided
by the reads, or by the frames of the DM reads: the profile by component behind issue
#25's ``plc.read``, 50-task and full-DM rows in benchmarks/README.md. C code (uvloop, the
socket, ``struct``, ``array``) is not counted: ``callgrind_api.py`` counts instructions.

    python benchmarks/opcodes_api.py [--cases read,tasks,dmarray] [--ops 2000] [--top 25]
        [--cap 5]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections import Counter
from collections.abc import Awaitable, Callable
from pathlib import Path
from types import FrameType
from typing import Any

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_session import free_port, start_responder

import aiofins

#: Reads (or frames) per traced operation of each case.
UNIT = {"read": 1, "tasks": 500, "dmarray": 33}


def tracer(opcodes: Counter[str], calls: Counter[str]) -> Any:
    def trace(frame: FrameType, event: str, arg: Any) -> Any:
        frame.f_trace_opcodes = True
        code = frame.f_code
        where = code.co_filename.split("/src/")[-1].split("site-packages/")[-1]
        key = f"{where}:{code.co_firstlineno}:{code.co_name}"
        calls[key] += event == "call"

        def local(frame: FrameType, event: str, arg: Any) -> Any:
            if event == "opcode":
                opcodes[key] += 1
            return local

        return local

    return trace


async def profile(port: int, case: str, ops: int, cap: int, top: int) -> None:
    url = f"udp://127.0.0.1:{port}?node=1"
    async with aiofins.connect(url, max_in_flight=max(cap, 50 if case == "tasks" else 1)) as plc:
        one: Callable[[], Awaitable[object]]
        if case == "dmarray":

            async def one() -> None:
                await plc.read_array("D0", 32768)

        elif case == "tasks":

            async def caller() -> None:  # 10 reads per task and operation
                for _ in range(10):
                    await plc.read("D100", 1)

            async def one() -> None:
                await asyncio.gather(*(caller() for _ in range(50)))

        else:

            async def one() -> None:
                await plc.read("D100", 1)

        for _ in range(20):
            await one()
        opcodes: Counter[str] = Counter()
        calls: Counter[str] = Counter()
        sys.settrace(tracer(opcodes, calls))
        try:
            for _ in range(ops):
                await one()
        finally:
            sys.settrace(None)
    n = ops * UNIT[case]
    per = "frame" if case == "dmarray" else "read"
    print(
        f"\n{case}: {sum(opcodes.values()) / n:,.0f} opcodes per {per}, "
        f"{sum(calls.values()) / n:.1f} calls"
    )
    print(f"{'opcodes':>8} {'calls':>6}  function")
    for key, count in opcodes.most_common(top):
        print(f"{count / n:8.1f} {calls[key] / n:6.2f}  {key}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="read,tasks,dmarray")
    parser.add_argument("--ops", type=int, default=2000, help="operations traced per case")
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--cap", type=int, default=5, help="max_in_flight (tasks: 50)")
    args = parser.parse_args()
    port = free_port()
    responder = start_responder(port, None)
    try:
        for case in args.cases.split(","):
            ops = max(1, args.ops // UNIT[case])
            anyio.run(
                profile, port, case, ops, args.cap, args.top, backend_options={"use_uvloop": True}
            )
    finally:
        responder.terminate()
        responder.wait()


if __name__ == "__main__":
    main()
