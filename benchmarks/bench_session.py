"""Session throughput and latency against the C FINS responder (UDP), asyncio and uvloop.

Builds ``fins_responder`` (``make -C <perf tools>``), runs it on a free loopback port and
measures, for each event loop: sequential 1-word reads, 50 reads in flight on one session
(50 tasks, and one ``request_many`` caller), and sequential 999-word reads. Every check
of the session stays on (SID matching, deadlines, stats). Prints a table; ``--json``
prints the rows as JSON.

    python benchmarks/bench_session.py                 # 3 s per case
    python benchmarks/bench_session.py --pin 0         # responder and client on CPU 0
    python benchmarks/bench_session.py --pin 0,1       # responder on CPU 0, client on CPU 1
    python benchmarks/bench_session.py --tcp           # FINS/TCP rows too

On a small VM a cross-core wake-up costs tens of microseconds, so pinning both to one core
shows the per-request cost of the client; one core each shows pipelined throughput.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import anyio

from aiofins.protocol.header import FinsAddress
from aiofins.session import Session
from aiofins.transport.tcp import TcpTransport
from aiofins.transport.udp import UdpTransport

PERF_TOOLS = Path(
    os.environ.get("AIOFINS_PERF_TOOLS", Path(__file__).resolve().parents[2] / "shared/tools/perf")
)


def read_params(word: int, count: int) -> bytes:
    return bytes((0x82, word >> 8, word & 0xFF, 0, count >> 8, count & 0xFF))


def free_port() -> int:
    """A port free for both UDP and TCP on 127.0.0.1 (the responder binds both)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:
            tcp.bind(("127.0.0.1", 0))
            port = int(tcp.getsockname()[1])
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
                try:
                    udp.bind(("127.0.0.1", port))
                except OSError:
                    continue
                return port
    raise RuntimeError("no free port")


def start_responder(port: int, cpu: int | None) -> subprocess.Popen[bytes]:
    subprocess.run(["make", "-s", "-C", str(PERF_TOOLS)], check=True)
    cmd = [str(PERF_TOOLS / "bin/fins_responder"), "-p", str(port), "-q"]
    if cpu is not None:
        cmd = ["taskset", "-c", str(cpu), *cmd]
    proc = subprocess.Popen(cmd)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:  # ready when TCP accepts
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return proc
        except OSError:
            time.sleep(0.01)
    proc.kill()
    raise RuntimeError("fins_responder did not start")


def summarise(case: str, loop: str, latencies: list[float], seconds: float) -> dict[str, Any]:
    latencies.sort()
    n = len(latencies)
    return {
        "loop": loop,
        "case": case,
        "requests": n,
        "req_s": n / seconds,
        "p50_us": statistics.median(latencies) * 1e6,
        "p99_us": latencies[min(n - 1, int(n * 0.99))] * 1e6,
    }


async def run_cases(
    port: int, duration: float, loop: str, tcp: bool = False
) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    clock = time.perf_counter
    transport = TcpTransport("127.0.0.1", port) if tcp else UdpTransport("127.0.0.1", port)
    session = Session(
        transport,
        source=FinsAddress(0, 2, 0),
        dest=FinsAddress(0, 1, 0),
        max_in_flight=50,
        timeout=2.0,
    )
    async with session:
        request = session.request

        async def sequential(case: str, count: int, expect: int) -> None:
            params = read_params(100, count)
            for _ in range(200):  # warm up
                await request(0x01, 0x01, params)
            lat: list[float] = []
            start = clock()
            end = start + duration
            now = start
            while now < end:
                t0 = now
                r = await request(0x01, 0x01, params)
                now = clock()
                lat.append(now - t0)
            if len(r.data) != expect:
                raise AssertionError("wrong reply size")
            rows.append(summarise(prefix + case, loop, lat, now - start))

        async def pipelined(case: str, width: int, count: int) -> None:
            params = read_params(100, count)
            lat: list[float] = []
            stop = clock() + duration

            async def worker() -> None:
                add = lat.append
                while True:
                    t0 = clock()
                    await request(0x01, 0x01, params)
                    t1 = clock()
                    add(t1 - t0)
                    if t1 >= stop:
                        return

            start = clock()
            async with anyio.create_task_group() as tg:
                for _ in range(width):
                    tg.start_soon(worker)
            rows.append(summarise(prefix + case, loop, lat, clock() - start))

        async def bulk(case: str, width: int, count: int, batch: int = 1000) -> None:
            """``request_many`` batches of ``batch`` commands, ``width`` on the wire."""
            commands = [(0x01, 0x01, read_params(100, count))] * batch
            await session.request_many(commands, window=width)  # warm up
            done = 0
            start = now = clock()
            end = start + duration
            first_lat = session.stats._lat_count
            while now < end:
                rs = await session.request_many(commands, window=width)
                done += len(rs)
                now = clock()
            if len(rs[-1].data) != 2 * count:
                raise AssertionError("wrong reply size")
            # Per-request round-trip times: the session's ring of the latest 1,024 replies.
            ring = session.stats._lat_ring
            n = min(session.stats._lat_count - first_lat, len(ring))
            row = summarise(prefix + case, loop, list(ring[:n]), now - start)
            row["requests"] = done
            row["req_s"] = done / (now - start)
            rows.append(row)

        prefix = "TCP " if tcp else ""
        await sequential("sequential 1 word", 1, 2)
        await pipelined("50 in flight, 1 word", 50, 1)
        await bulk("pipelined request_many, 50 in flight, 1 word", 50, 1)
        if not tcp:
            await sequential("sequential 999 words", 999, 1998)
            await pipelined("50 in flight, 999 words", 50, 999)
        stats = session.stats
        if stats.timeouts or stats.malformed or stats.unsolicited:
            raise AssertionError(f"faults during the benchmark: {stats}")
    return rows


async def raw_baseline(port: int, duration: float, loop_name: str) -> list[dict[str, Any]]:
    """The floor for any asyncio client: a bare DatagramProtocol and one future per request."""
    import asyncio

    frame = bytes((0x80, 0, 2, 0, 1, 0, 0, 2, 0, 0, 0x01, 0x01)) + read_params(100, 1)

    class Ping(asyncio.DatagramProtocol):
        fut: asyncio.Future[bytes] | None = None

        def datagram_received(self, data: bytes, addr: Any) -> None:
            if self.fut is not None and not self.fut.done():
                self.fut.set_result(data)

    loop = asyncio.get_running_loop()
    transport, proto = await loop.create_datagram_endpoint(Ping, remote_addr=("127.0.0.1", port))
    lat: list[float] = []
    clock = time.perf_counter
    try:
        start = now = clock()
        end = start + duration
        while now < end:
            t0 = now
            proto.fut = loop.create_future()
            transport.sendto(frame)
            await proto.fut
            now = clock()
            lat.append(now - t0)
    finally:
        transport.close()
    return [summarise("bare protocol, sequential", f"{loop_name}", lat, now - start)]


def c_baseline(port: int, duration: float, cpu: int | None) -> list[dict[str, Any]]:
    rows = []
    for case, extra in (("sequential 1 word", []), ("50 in flight, 1 word", ["-w", "50"])):
        cmd = [str(PERF_TOOLS / "bin/fins_pingpong"), "-p", str(port), "-d", str(duration)]
        if cpu is not None:
            cmd = ["taskset", "-c", str(cpu), *cmd]
        out = subprocess.run([*cmd, *extra], capture_output=True, text=True, check=True).stdout
        fields = dict(item.split("=", 1) for item in out.split() if "=" in item)
        rows.append(
            {
                "loop": "C pingpong",
                "case": case,
                "requests": int(fields["n"]),
                "req_s": float(fields["req_s"]),
                "p50_us": float(fields["p50_us"]),
                "p99_us": float(fields["p99_us"]),
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3.0, help="seconds per case")
    parser.add_argument("--pin", default="", help="CPU for responder[,client], e.g. 0 or 0,1")
    parser.add_argument("--json", action="store_true", help="print JSON rows")
    parser.add_argument("--no-c", action="store_true", help="skip the C baseline")
    parser.add_argument("--tcp", action="store_true", help="also run FINS/TCP (1-word cases)")
    args = parser.parse_args()
    cpus = [int(c) for c in args.pin.split(",") if c.strip()]
    server_cpu = cpus[0] if cpus else None
    client_cpu = cpus[1] if len(cpus) > 1 else server_cpu
    if client_cpu is not None:
        os.sched_setaffinity(0, {client_cpu})
    port = free_port()
    proc = start_responder(port, server_cpu)
    rows: list[dict[str, Any]] = []
    try:
        if not args.no_c:
            rows += c_baseline(port, args.duration, client_cpu)
        rows += anyio.run(raw_baseline, port, args.duration, "asyncio", backend="asyncio")
        rows += anyio.run(run_cases, port, args.duration, "asyncio", backend="asyncio")
        try:
            import uvloop  # noqa: F401

            uv = {"use_uvloop": True}
            rows += anyio.run(
                raw_baseline, port, args.duration, "uvloop", backend="asyncio", backend_options=uv
            )
            rows += anyio.run(
                run_cases,
                port,
                args.duration,
                "uvloop",
                backend="asyncio",
                backend_options={"use_uvloop": True},
            )
        except ImportError:
            print("uvloop not installed: skipped", file=sys.stderr)
        rows += anyio.run(run_cases, port, args.duration, "trio", backend="trio")
        if args.tcp:
            rows += anyio.run(run_cases, port, args.duration, "asyncio", True, backend="asyncio")
            rows += anyio.run(run_cases, port, args.duration, "trio", True, backend="trio")
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{'loop':<11} {'case':<46} {'req/s':>9} {'p50 µs':>8} {'p99 µs':>8}")
    for row in rows:
        print(
            f"{row['loop']:<11} {row['case']:<46} {row['req_s']:>9.0f} "
            f"{row['p50_us']:>8.1f} {row['p99_us']:>8.1f}"
        )


if __name__ == "__main__":
    main()
