"""Instructions per operation of each case of issue #25, against the C responder (callgrind).

Wall clock on a shared VM moves by ±30 % and more; instruction counts do not. Each case runs
under ``valgrind --tool=callgrind`` twice, with a small and a large number of operations; the
difference divided by the difference in operations is the marginal cost of one, free of
start-up and imports. The C responder (../shared/tools/perf) answers in its own process, which
callgrind does not count; what the kernel does for a syscall is not counted either (user
space only). Cases (uvloop unless named; sequential unless named):

- ``bare``: the bare ``DatagramProtocol`` client of ``bench_session.py`` (one future per
  request), per request; ``bare-stock``: the same on stock asyncio;
- ``read``: ``plc.read("D100", 1)``; ``read-stock``: the same on stock asyncio;
- ``fins``: PyPI ``fins``' ``memory_area_read`` of 1 word and its decode (synchronous);
- ``sync``: ``aiofins.sync``'s ``plc.read("D100", 1)``, run in the calling thread on a
  blocking socket; ``sync-tcp``: the same over FINS/TCP; ``sync-loop``: with
  ``backend="asyncio"``, each call sent to the private loop's thread (callgrind counts both
  threads);
- ``tasks``: 50 tasks x ``plc.read("D100", 1)`` on one client, per read;
- ``dm`` / ``dmarray``: ``plc.read("D0", 32768)`` / ``plc.read_array("D0", 32768)``, per
  frame (33 per read);
- ``daemon``: ``bench_api.hand_written_daemon`` over 10 C responders at 50 ms, 1 and 4 s
  measured (after its 1 s warm-up), per scan (the scans it made, not a set number: under
  valgrind it may fall behind its pace).

The Poller's instructions per scan: ``callgrind_poller.py``.

    python benchmarks/callgrind_api.py [--cases bare,read,fins,...]

``--inner CASE PORTS N`` runs one workload without valgrind (what the outer run starts).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_session import free_port, free_ports, read_params, start_responder

#: (small, large) operations per case, and operations counted per unit.
COUNTS: dict[str, tuple[int, int, int]] = {
    "bare": (500, 3_000, 1),
    "bare-stock": (500, 3_000, 1),
    "read": (500, 3_000, 1),
    "read-stock": (500, 3_000, 1),
    "fins": (500, 3_000, 1),
    "sync": (500, 3_000, 1),
    "sync-tcp": (500, 3_000, 1),
    "sync-loop": (300, 1_800, 1),
    "tasks": (1_000, 4_000, 1),
    "dm": (3, 13, 33),
    "dmarray": (3, 13, 33),
    "daemon": (1, 4, 0),  # seconds measured; per scan made
}


async def _bare(port: int, n: int) -> None:
    loop = asyncio.get_running_loop()
    frame = bytes((0x80, 0, 2, 0, 1, 0, 0, 2, 0, 0, 0x01, 0x01)) + read_params(100, 1)
    frames = [frame[:9] + bytes((sid,)) + frame[10:] for sid in range(256)]
    waiting: dict[int, asyncio.Future[bytes]] = {}

    class Bare(asyncio.DatagramProtocol):
        def datagram_received(self, data: bytes, addr: Any) -> None:
            future = waiting.pop(data[9], None)
            if future is not None and not future.done():
                future.set_result(data)

    transport, _ = await loop.create_datagram_endpoint(Bare, remote_addr=("127.0.0.1", port))
    try:
        for i in range(n):
            sid = i & 0xFF
            future = waiting[sid] = loop.create_future()
            transport.sendto(frames[sid])
            data = await future
            int.from_bytes(data[14:16], "big")
    finally:
        transport.close()


async def _reads(port: int, n: int, case: str) -> None:
    import aiofins

    async with aiofins.connect(f"udp://127.0.0.1:{port}?node=1", max_in_flight=50) as plc:
        if case in ("dm", "dmarray"):
            big = plc.read_array if case == "dmarray" else plc.read
            for _ in range(n):
                await big("D0", 32768)
        elif case == "tasks":

            async def caller(count: int) -> None:
                for _ in range(count):
                    await plc.read("D100", 1)

            await asyncio.gather(*(caller(n // 50) for _ in range(50)))
        else:
            read = plc.read
            for _ in range(n):
                await read("D100", 1)


def _fins(port: int, n: int) -> None:
    import fins.udp  # type: ignore[import-untyped]  # PyPI fins has no type hints

    conn = fins.udp.UDPFinsConnection()
    conn.connect("127.0.0.1", port=port, bind_port=0)
    conn.dest_node_add, conn.srce_node_add = 1, 2
    area = fins.udp.FinsPLCMemoryAreas().DATA_MEMORY_WORD
    read = conn.memory_area_read
    for _ in range(n):
        int.from_bytes(read(area, b"\x00\x64\x00", 1)[-2:], "big")


def _sync(port: int, n: int, scheme: str = "udp", backend: str | None = None) -> None:
    import aiofins.sync

    url = f"udp://127.0.0.1:{port}?node=1" if scheme == "udp" else f"tcp://127.0.0.1:{port}"
    with aiofins.sync.connect(url, backend=backend) as plc:
        read = plc.read
        for _ in range(n):
            read("D100", 1)


def _workload(case: str, ports: list[int], n: int) -> None:
    uv: dict[str, Any] = {}
    if not case.endswith("stock") and case != "fins" and not case.startswith("sync"):
        import uvloop

        uv = {"loop_factory": uvloop.new_event_loop}
    if case.startswith("bare"):
        _run(_bare(ports[0], n), uv)
    elif case == "fins":
        _fins(ports[0], n)
    elif case == "sync":
        _sync(ports[0], n)
    elif case == "sync-tcp":
        _sync(ports[0], n, "tcp")
    elif case == "sync-loop":
        _sync(ports[0], n, backend="asyncio")
    elif case == "daemon":
        from bench_api import hand_written_daemon

        done: list[int] = []
        _run(hand_written_daemon(ports, 0.05, float(n), True, done), uv)
        print(done[0])
    else:
        _run(_reads(ports[0], n, case.removesuffix("-stock")), uv)


def _run(coro: Any, options: dict[str, Any]) -> None:
    factory = options.get("loop_factory")
    loop = factory() if factory else asyncio.new_event_loop()
    try:
        loop.run_until_complete(coro)
    finally:
        loop.close()


def _instructions(case: str, ports: list[int], n: int) -> tuple[int, str]:
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "callgrind.out")
        command = [
            "valgrind",
            "--tool=callgrind",
            f"--callgrind-out-file={out}",
            sys.executable,
            __file__,
            "--inner",
            case,
            ",".join(map(str, ports)),
            str(n),
        ]
        run = subprocess.run(command, check=True, capture_output=True, text=True)
        with open(out) as f:
            text = f.read()
    match = re.search(r"^(?:summary|totals): (\d+)", text, re.MULTILINE)
    assert match, "no totals in callgrind's output"
    return int(match.group(1)), run.stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=",".join(COUNTS))
    parser.add_argument("--inner", nargs=3, metavar=("CASE", "PORTS", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inner:
        case, ports, n = args.inner
        _workload(case, [int(p) for p in ports.split(",")], int(n))
        return
    ports = [free_port()]
    procs = [start_responder(ports[0], None)]
    try:
        for case in args.cases.split(","):
            low, high, unit = COUNTS[case]
            if case == "daemon" and len(ports) == 1:
                ports = [ports[0], *free_ports(9)]
                procs += [start_responder(port, None) for port in ports[1:]]
            small, said_small = _instructions(case, ports, low)
            large, said_large = _instructions(case, ports, high)
            if unit:
                per = (large - small) / (high - low) / unit
            else:  # the daemon says how many scans it made
                per = (large - small) / (int(said_large) - int(said_small))
            what = {0: "scan", 1: "op"}.get(unit, "frame")
            print(f"{case:10s} {per / 1000:8.1f}k instructions per {what}", flush=True)
    finally:
        for proc in procs:
            proc.terminate()
            proc.wait()


if __name__ == "__main__":
    main()
