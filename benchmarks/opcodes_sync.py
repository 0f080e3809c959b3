"""Python opcodes per sequential read, by function: ``aiofins.sync`` and PyPI ``fins``.

``sys.settrace`` opcode events, not timed. Against the C responder of ../shared/tools/perf,
after 500 untimed reads the next ``--reads`` of ``plc.read("D100", 1)`` (``aiofins.sync``
over UDP, the calling thread driving the session on a blocking socket) and of PyPI ``fins``'
``memory_area_read`` of D100 with its decode are traced; each Python function's opcodes (and
calls) are divided by the reads: the profile by component behind the ``aiofins.sync`` row of
benchmarks/README.md. C code (the socket, ``struct``) is not counted: ``callgrind_api.py``
counts instructions.

    python benchmarks/opcodes_sync.py [--reads 2000] [--top 30]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

WARM_UP = 500


def profile(read: Callable[[], object], reads: int) -> tuple[Counter[str], Counter[str]]:
    """Opcodes and calls per function over ``reads`` calls of ``read``."""
    opcodes: Counter[str] = Counter()
    calls: Counter[str] = Counter()

    def tracer(frame: FrameType, event: str, arg: Any) -> Any:
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

    for _ in range(WARM_UP):
        read()
    sys.settrace(tracer)
    try:
        for _ in range(reads):
            read()
    finally:
        sys.settrace(None)
    return opcodes, calls


def show(name: str, opcodes: Counter[str], calls: Counter[str], reads: int, top: int) -> None:
    total = sum(opcodes.values()) / reads
    print(f"\n{name}: {total:,.0f} opcodes per read, {sum(calls.values()) / reads:.1f} calls")
    print(f"{'opcodes':>8} {'calls':>6}  function")
    for key, count in opcodes.most_common(top):
        print(f"{count / reads:8.1f} {calls[key] / reads:6.2f}  {key}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reads", type=int, default=2000)
    parser.add_argument("--top", type=int, default=30)
    args = parser.parse_args()

    import fins.udp  # type: ignore[import-untyped]  # PyPI fins has no type hints
    from bench_session import free_port, start_responder

    import aiofins.sync

    port = free_port()
    responder = start_responder(port, None)
    try:
        with aiofins.sync.connect(f"udp://127.0.0.1:{port}?node=1") as plc:
            read = plc.read
            ops, calls = profile(lambda: read("D100", 1), args.reads)
        show("aiofins.sync plc.read", ops, calls, args.reads, args.top)
        conn = fins.udp.UDPFinsConnection()
        conn.connect("127.0.0.1", port=port, bind_port=0)
        conn.dest_node_add, conn.srce_node_add = 1, 2
        area = fins.udp.FinsPLCMemoryAreas().DATA_MEMORY_WORD
        fins_read = conn.memory_area_read
        try:
            ops, calls = profile(
                lambda: int.from_bytes(fins_read(area, b"\x00\x64\x00", 1)[-2:], "big"),
                args.reads,
            )
        finally:
            conn.fins_socket.close()
        show("PyPI fins memory_area_read", ops, calls, args.reads, args.top)
    finally:
        responder.kill()
        responder.wait()


if __name__ == "__main__":
    main()
