"""Session throughput against the C FINS responder (UDP, FINS/TCP): asyncio, uvloop, trio.

Builds ``fins_responder`` (``make -C <perf tools>``), runs it on a free loopback port and
measures, for each event loop: sequential 1-word reads, 50 reads in flight on one session
(50 tasks, and one ``request_many`` caller), and 999-word reads, next to a bare asyncio
protocol and the C client ``fins_pingpong``. Every check of the session stays on (SID
matching, deadlines, stats).

The VM is noisy, so the cases run in ``--rounds`` rounds; within a round each C case runs
right before the Python cases of the same kind, and the table shows medians over the rounds
with ``xC``, the median of the per-round ratio to the matching C row. ``--json`` prints
every per-round row and the medians.

    python benchmarks/bench_session.py                    # 3 rounds, 2 s per case
    python benchmarks/bench_session.py --cases seq,bulk   # only some cases
    python benchmarks/bench_session.py --pin 0            # responder and client on CPU 0
    python benchmarks/bench_session.py --pin 0,1          # responder on CPU 0, client on CPU 1
    python benchmarks/bench_session.py --tcp              # FINS/TCP rows too

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
from collections.abc import Callable, Coroutine, Sequence
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

Row = dict[str, Any]

#: ``--cases`` keys, in the order a round runs them.
CASE_KEYS = ("seq", "inflight", "bulk", "999")
SEQ_1 = "sequential 1 word"
INFLIGHT_1 = "50 in flight, 1 word"
BULK_1 = "pipelined request_many, 50 in flight, 1 word"
SEQ_999 = "sequential 999 words"
INFLIGHT_999 = "50 in flight, 999 words"
BARE_SEQ = "bare protocol, sequential"
BARE_INFLIGHT = "bare protocol, 50 in flight"
C_LOOP = "C pingpong"
#: Targets: (loop, sequential xC, 50-in-flight req/s), each checked over UDP and FINS/TCP.
TARGETS = (("asyncio", 0.55, 90_000.0), ("uvloop", 0.73, 150_000.0))


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


def free_ports(count: int) -> list[int]:
    """``count`` different ports, each as :func:`free_port` finds one."""
    ports: list[int] = []
    while len(ports) < count:
        port = free_port()
        if port not in ports:
            ports.append(port)
    return ports


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


def summarise(case: str, loop: str, latencies: list[float], seconds: float) -> Row:
    latencies.sort()
    n = len(latencies)
    return {
        "loop": loop,
        "case": case,
        "requests": n,
        "req_s": n / seconds,
        "p50_us": statistics.median(latencies) * 1e6 if n else float("nan"),
        "p99_us": latencies[min(n - 1, int(n * 0.99))] * 1e6 if n else float("nan"),
    }


async def run_cases(
    port: int, duration: float, loop: str, cases: Sequence[str], tcp: bool = False
) -> list[Row]:
    """The session cases named by ``cases`` (``CASE_KEYS``), one fresh session."""
    rows: list[Row] = []
    clock = time.perf_counter
    transport = TcpTransport("127.0.0.1", port) if tcp else UdpTransport("127.0.0.1", port)
    session = Session(
        transport,
        source=FinsAddress(0, 2, 0),
        dest=FinsAddress(0, 1, 0),
        max_in_flight=50,
        timeout=2.0,
    )
    prefix = "TCP " if tcp else ""
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
            stats = session.stats
            first_lat = getattr(stats, "_lat_count", 0)
            done = 0
            start = now = clock()
            end = start + duration
            while now < end:
                rs = await session.request_many(commands, window=width)
                done += len(rs)
                now = clock()
            if len(rs[-1].data) != 2 * count:
                raise AssertionError("wrong reply size")
            # Per-request round-trip times: the session's ring of the latest replies
            # (private to the session; no p50/p99 if it goes away).
            ring: list[float] = list(getattr(stats, "_lat_ring", []))
            n = min(getattr(stats, "_lat_count", 0) - first_lat, len(ring))
            row = summarise(prefix + case, loop, ring[:n], now - start)
            row["requests"] = done
            row["req_s"] = done / (now - start)
            rows.append(row)

        for key in cases:
            if key == "seq":
                await sequential(SEQ_1, 1, 2)
            elif key == "inflight":
                await pipelined(INFLIGHT_1, 50, 1)
            elif key == "bulk":
                await bulk(BULK_1, 50, 1)
            elif key == "999" and not tcp:
                await sequential(SEQ_999, 999, 1998)
                await pipelined(INFLIGHT_999, 50, 999)
        stats = session.stats
        if stats.timeouts or stats.malformed or stats.unsolicited:
            raise AssertionError(f"faults during the benchmark: {stats}")
    return rows


async def raw_baseline(
    port: int, duration: float, loop_name: str, cases: Sequence[str]
) -> list[Row]:
    """The floor for any asyncio client: a bare DatagramProtocol and one future per request.

    ``seq``: one request at a time. ``inflight``: 50 tasks on one endpoint, futures keyed by
    SID (byte 9; a counter & 0xFF, so 50 in flight never collide) and nothing else checked.
    """
    import asyncio

    frame = bytes((0x80, 0, 2, 0, 1, 0, 0, 2, 0, 0, 0x01, 0x01)) + read_params(100, 1)
    frames = [frame[:9] + bytes((sid,)) + frame[10:] for sid in range(256)]

    class Bare(asyncio.DatagramProtocol):
        def __init__(self) -> None:
            self.fut: asyncio.Future[bytes] | None = None
            self.waiting: dict[int, asyncio.Future[bytes]] = {}

        def datagram_received(self, data: bytes, addr: Any) -> None:
            fut = self.fut
            if fut is not None:  # sequential
                if not fut.done():
                    fut.set_result(data)
                return
            fut = self.waiting.pop(data[9], None)
            if fut is not None:
                fut.set_result(data)

    loop = asyncio.get_running_loop()
    clock = time.perf_counter
    rows: list[Row] = []

    async def sequential(proto: Bare, transport: asyncio.DatagramTransport) -> None:
        lat: list[float] = []
        start = now = clock()
        end = start + duration
        while now < end:
            t0 = now
            proto.fut = loop.create_future()
            transport.sendto(frame)
            await proto.fut
            now = clock()
            lat.append(now - t0)
        rows.append(summarise(BARE_SEQ, loop_name, lat, now - start))

    async def in_flight(proto: Bare, transport: asyncio.DatagramTransport, width: int) -> None:
        proto.fut = None
        waiting = proto.waiting
        sids = [0]
        lat: list[float] = []
        stop = clock() + duration

        async def worker() -> None:
            add = lat.append
            while True:
                sid = sids[0] & 0xFF
                sids[0] = sid + 1
                fut = loop.create_future()
                waiting[sid] = fut
                t0 = clock()
                transport.sendto(frames[sid])
                await fut
                t1 = clock()
                add(t1 - t0)
                if t1 >= stop:
                    return

        start = clock()
        tasks = [loop.create_task(worker()) for _ in range(width)]
        # No timeouts on the request path: a lost datagram strands its task, so stop waiting
        # a second after the end and count the stranded ones.
        _, stranded = await asyncio.wait(tasks, timeout=duration + 1.0)
        for task in stranded:
            task.cancel()
        row = summarise(BARE_INFLIGHT, loop_name, lat, clock() - start)
        if stranded:
            row["stranded"] = len(stranded)
            print(f"{loop_name} {BARE_INFLIGHT}: {len(stranded)} lost", file=sys.stderr)
        rows.append(row)

    transport, proto = await loop.create_datagram_endpoint(Bare, remote_addr=("127.0.0.1", port))
    try:
        for key in cases:
            if key == "seq":
                await sequential(proto, transport)
            elif key == "inflight":
                await in_flight(proto, transport, 50)
    finally:
        transport.close()
    return rows


def c_baseline(
    port: int, duration: float, cpu: int | None, cases: Sequence[str], tcp: bool = False
) -> list[Row]:
    """``fins_pingpong`` rows: ``seq``/``inflight`` (1 word), ``seq999``/``inflight999``.

    ``tcp``: over FINS/TCP (1-word cases only), rows named ``TCP ...``.
    """
    runs = {
        "seq": (SEQ_1, ["-w", "1"]),
        "inflight": (INFLIGHT_1, ["-w", "50"]),
        "seq999": (SEQ_999, ["-w", "1", "-c", "999"]),
        "inflight999": (INFLIGHT_999, ["-w", "50", "-c", "999"]),
    }
    rows = []
    for key in cases:
        case, extra = runs[key]
        if tcp:
            if key not in ("seq", "inflight"):
                continue
            case, extra = "TCP " + case, [*extra, "-t"]
        cmd = [str(PERF_TOOLS / "bin/fins_pingpong"), "-p", str(port), "-d", str(duration)]
        if cpu is not None:
            cmd = ["taskset", "-c", str(cpu), *cmd]
        out = subprocess.run([*cmd, *extra], capture_output=True, text=True, check=True).stdout
        fields = dict(item.split("=", 1) for item in out.split() if "=" in item)
        rows.append(
            {
                "loop": C_LOOP,
                "case": case,
                "requests": int(fields["n"]),
                "req_s": float(fields["req_s"]),
                "p50_us": float(fields["p50_us"]),
                "p99_us": float(fields["p99_us"]),
            }
        )
    return rows


#: The C row each case is compared with (``xC``), by case name without ``TCP ``.
C_MATCH = {
    SEQ_1: SEQ_1,
    INFLIGHT_1: INFLIGHT_1,
    BULK_1: INFLIGHT_1,
    SEQ_999: SEQ_999,
    INFLIGHT_999: INFLIGHT_999,
    BARE_SEQ: SEQ_1,
    BARE_INFLIGHT: INFLIGHT_1,
}
CASE_ORDER = (BARE_SEQ, BARE_INFLIGHT, SEQ_1, INFLIGHT_1, BULK_1, SEQ_999, INFLIGHT_999)

#: An event loop: name, anyio backend, backend options.
Loop = tuple[str, str, dict[str, Any]]
Bench = Callable[..., Coroutine[Any, Any, list[Row]]]


def event_loops() -> list[Loop]:
    loops: list[Loop] = [("asyncio", "asyncio", {})]
    try:
        import uvloop  # noqa: F401

        loops.append(("uvloop", "asyncio", {"use_uvloop": True}))
    except ImportError:
        print("uvloop not installed: skipped", file=sys.stderr)
    loops.append(("trio", "trio", {}))
    return loops


def on_loop(loop: Loop, func: Bench, *args: Any) -> list[Row]:
    _, backend, options = loop
    rows: list[Row] = anyio.run(func, *args, backend=backend, backend_options=options)
    return rows


def run_round(
    port: int, args: argparse.Namespace, loops: list[Loop], cases: Sequence[str], cpu: int | None
) -> list[Row]:
    """One round: each kind of case runs C first, then the bare protocol, then every loop."""
    d = args.duration
    rows: list[Row] = []
    stages = (
        (["seq"], ["seq"]),
        (["inflight"], ["inflight", "bulk"]),
        (["seq999", "inflight999"], ["999"]),
    )
    for c_cases, keys in stages:
        keys = [k for k in keys if k in cases]
        if not keys:
            continue
        if not args.no_c:
            rows += c_baseline(port, d, cpu, c_cases)
        for loop in loops:
            if loop[1] == "asyncio" and {"seq", "inflight"} & set(keys):
                rows += on_loop(loop, raw_baseline, port, d, loop[0], keys)
        for loop in loops:
            rows += on_loop(loop, run_cases, port, d, loop[0], keys)
        if args.tcp and "999" not in keys:
            if not args.no_c:
                rows += c_baseline(port, d, cpu, c_cases, tcp=True)
            for loop in loops:
                rows += on_loop(loop, run_cases, port, d, loop[0], keys, True)
    c_rows = {row["case"]: row["req_s"] for row in rows if row["loop"] == C_LOOP}
    for row in rows:
        case = row["case"]
        prefix = "TCP " if case.startswith("TCP ") else ""
        c = c_rows.get(prefix + C_MATCH[case.removeprefix(prefix)])
        row["x_c"] = row["req_s"] / c if c else None
    return rows


def medians(rows: list[Row], loops: list[Loop]) -> list[Row]:
    """Per (loop, case): req/s median, min, max; p50, p99 and xC medians over the rounds."""
    groups: dict[tuple[str, str], list[Row]] = {}
    for row in rows:
        groups.setdefault((row["loop"], row["case"]), []).append(row)
    order = [C_LOOP, *(loop[0] for loop in loops)]

    def key(item: tuple[tuple[str, str], list[Row]]) -> tuple[int, bool, int]:
        loop, case = item[0]
        tcp = case.startswith("TCP ")
        return order.index(loop), tcp, CASE_ORDER.index(case.removeprefix("TCP "))

    out: list[Row] = []
    for (loop, case), group in sorted(groups.items(), key=key):
        rates = [r["req_s"] for r in group]
        ratios = [r["x_c"] for r in group if r.get("x_c") is not None]
        out.append(
            {
                "loop": loop,
                "case": case,
                "rounds": len(group),
                "req_s": statistics.median(rates),
                "req_s_min": min(rates),
                "req_s_max": max(rates),
                "x_c": statistics.median(ratios) if ratios else None,
                "p50_us": statistics.median(r["p50_us"] for r in group),
                "p99_us": statistics.median(r["p99_us"] for r in group),
            }
        )
    return out


def targets(table: list[Row], loops: list[Loop]) -> list[Row]:
    """Sequential xC and the best 50-in-flight req/s against the targets, per loop."""
    names = {loop[0] for loop in loops}
    by = {(row["loop"], row["case"]): row for row in table}
    out: list[Row] = []

    def goal(loop: str, target: str, value: float | None, want: float) -> None:
        met = None if value is None else value >= want
        out.append({"loop": loop, "target": target, "value": value, "goal": want, "met": met})

    tcp = any(row["case"].startswith("TCP ") for row in table)
    for prefix, medium in (("", "UDP"), ("TCP ", "TCP")) if tcp else (("", "UDP"),):
        for loop, seq_target, inflight_target in TARGETS:
            if loop in names:
                seq = by.get((loop, prefix + SEQ_1))
                goal(loop, f"{medium} sequential xC", seq["x_c"] if seq else None, seq_target)
                rates = [
                    by[(loop, prefix + c)]["req_s"]
                    for c in (INFLIGHT_1, BULK_1)
                    if (loop, prefix + c) in by
                ]
                goal(
                    loop,
                    f"{medium} 50 in flight req/s",
                    max(rates) if rates else None,
                    inflight_target,
                )
    return out


def print_table(table: list[Row], goals: list[Row], rounds: int) -> None:
    print(f"medians over {rounds} round(s); xC: median of the per-round ratio to the C row")
    print(
        f"{'loop':<10} {'case':<46} {'req/s':>8} {'min':>8} {'max':>8} {'xC':>5} "
        f"{'p50 µs':>7} {'p99 µs':>7}"
    )
    for row in table:
        x_c = "" if row["x_c"] is None else f"{row['x_c']:.2f}"
        print(
            f"{row['loop']:<10} {row['case']:<46} {row['req_s']:>8.0f} {row['req_s_min']:>8.0f} "
            f"{row['req_s_max']:>8.0f} {x_c:>5} {row['p50_us']:>7.1f} {row['p99_us']:>7.1f}"
        )
    if not goals:
        return
    print("\ntargets")
    for goal in goals:
        verdict = {None: "n/a", True: "met", False: "NOT met"}[goal["met"]]
        if "sequential" in goal["target"]:
            value = "n/a" if goal["value"] is None else f"{goal['value']:.2f} xC"
            want = f"≥ {goal['goal']:.2f} xC"
        else:
            value = "n/a" if goal["value"] is None else f"{goal['value'] / 1e3:.1f}k/s"
            want = f"≥ {goal['goal'] / 1e3:.0f}k/s"
        print(f"  {goal['loop']:<8} {goal['target']:<24} {value:>10}  {want:<12} {verdict}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=2.0, help="seconds per case per round")
    parser.add_argument("--rounds", type=int, default=3, help="rounds (medians are printed)")
    parser.add_argument(
        "--cases", default=",".join(CASE_KEYS), help="comma list of " + ",".join(CASE_KEYS)
    )
    parser.add_argument("--pin", default="", help="CPU for responder[,client], e.g. 0 or 0,1")
    parser.add_argument("--json", action="store_true", help="print per-round rows and medians")
    parser.add_argument("--no-c", action="store_true", help="skip the C baseline")
    parser.add_argument(
        "--tcp", action="store_true", help="also run FINS/TCP (1-word cases, C client too)"
    )
    args = parser.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = set(cases) - set(CASE_KEYS)
    if unknown or not cases or args.rounds < 1:
        parser.error(f"--cases takes {','.join(CASE_KEYS)}; --rounds >= 1")
    cpus = [int(c) for c in args.pin.split(",") if c.strip()]
    server_cpu = cpus[0] if cpus else None
    client_cpu = cpus[1] if len(cpus) > 1 else server_cpu
    if client_cpu is not None:
        os.sched_setaffinity(0, {client_cpu})
    loops = event_loops()
    port = free_port()
    proc = start_responder(port, server_cpu)
    rows: list[Row] = []
    try:
        for n in range(args.rounds):
            print(f"round {n + 1}/{args.rounds}", file=sys.stderr)
            for row in run_round(port, args, loops, cases, client_cpu):
                rows.append({"round": n + 1, **row})
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    table = medians(rows, loops)
    goals = targets(table, loops)
    if args.json:
        print(json.dumps({"rounds": rows, "medians": table, "targets": goals}, indent=2))
        return
    print_table(table, goals, args.rounds)


if __name__ == "__main__":
    main()
