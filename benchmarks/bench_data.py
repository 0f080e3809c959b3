"""Big and typed data: full DM read, a 200-tag scan, 200 PLCs polled through the pool.

* Full DM read (32,768 words) over UDP from the C responder (../shared/tools/perf): frames sent
  and wall time, sequential (one frame in flight) vs pipelined (the session's in-flight cap).
* A 200-tag mixed list (floats, 32-bit counters, bits, scattered words) against the virtual PLC
  (``aiofins simulate`` in a subprocess; the C responder has no 0104): frames per scan, scans/s.
* 200 PLC endpoints (200 C responders on consecutive ports) polled through one Pool and Poller:
  total reads/s and the CPU time this process used.

    python benchmarks/bench_data.py [--seconds 5] [--uvloop]
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import anyio

import aiofins
from aiofins.poller import Poller
from aiofins.pool import Pool

PERF_TOOLS = Path(
    os.environ.get("AIOFINS_PERF_TOOLS", Path(__file__).resolve().parents[2] / "shared/tools/perf")
)


def tag_list() -> dict[str, str]:
    """200 tags: 60 float32, 40 uint32 counters, 60 bits, 40 scattered words."""
    tags: dict[str, str] = {}
    for i in range(60):
        tags[f"temp{i}"] = f"D{1000 + 2 * i}:float32"
    for i in range(40):
        tags[f"count{i}"] = f"D{2000 + 2 * i}:uint32"
    for i in range(60):
        tags[f"bit{i}"] = f"CIO {i // 16}.{i % 16:02d}"
    for i in range(40):
        tags[f"word{i}"] = f"D{5000 + 250 * i}"
    return tags


@contextmanager
def responders(count: int, base_port: int) -> Iterator[list[int]]:
    subprocess.run(["make", "-s", "-C", str(PERF_TOOLS)], check=True)
    exe = PERF_TOOLS / "bin" / "fins_responder"
    procs = [
        subprocess.Popen([str(exe), "-p", str(base_port + i)], stderr=subprocess.DEVNULL)
        for i in range(count)
    ]
    try:
        time.sleep(0.3)  # let them bind (a benchmark, not a test)
        yield [base_port + i for i in range(count)]
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait()


@contextmanager
def simulator() -> Iterator[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "aiofins.cli", "simulate", "--udp", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    url = ""
    for line in proc.stdout:
        m = re.match(r"listening on (udp://\S+)", line)
        if m:
            url = m.group(1)
            break
    try:
        yield url
    finally:
        proc.terminate()
        proc.wait()


async def full_dm(port: int) -> None:
    url = f"udp://127.0.0.1:{port}?node=1"
    for label, cap in (("sequential", 1), ("pipelined, 5 in flight", 5), ("pipelined, 20", 20)):
        async with aiofins.connect(url, max_in_flight=cap) as plc:
            await plc.read("D0", 999)  # warm up
            before = plc.session.stats.completed
            start = time.perf_counter()
            rounds = 20
            for _ in range(rounds):
                words = await plc.read("D0", 32768)
            elapsed = (time.perf_counter() - start) / rounds
            frames = (plc.session.stats.completed - before) // rounds
            assert words[:3] == [0, 1, 2]
            print(f"  full DM read, {label:<24} {frames:>3} frames  {elapsed * 1000:7.1f} ms")


async def tag_scan(url: str, seconds: float) -> None:
    async with aiofins.connect(url) as plc:
        plan = plc.compile_tags(tag_list())
        await plc.read_tags(plan)
        scans = 0
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            await plc.read_tags(plan)
            scans += 1
        rate = scans / (time.perf_counter() - start)
        print(
            f"  200-tag scan: {plan.frame_count} frames per scan "
            f"({len(plan.runs)} x 0101, {len(plan.multiple)} x 0104), {rate:.0f} scans/s"
        )


async def many_plcs(ports: list[int], seconds: float, interval: float = 0.1) -> None:
    """Every PLC polled at ``interval`` by one Pool and Poller; measured after a 1 s warm-up.

    (The first scans open 200 sessions at once and overrun; the steady state is what a
    long-running daemon sees.)
    """
    tags = {"a": "D0:float32", "b": "D2:uint32", "c": "D4.03", "d": "D7"}  # one 0101 frame
    async with Pool(timeout=1.0) as pool, Poller(pool, buffer=1024) as poller:
        for port in ports:
            poller.add_group(str(port), f"udp://127.0.0.1:{port}?node=1", tags, interval=interval)
        scans = 0

        async def consume() -> None:
            nonlocal scans
            async for snap in poller:
                scans += 1
                assert snap.error is None, snap.error

        async with anyio.create_task_group() as tg:
            tg.start_soon(consume)
            await anyio.sleep(1.0)
            missed0 = sum(g.missed for g in poller.groups.values())
            scans0 = scans
            usage0 = resource.getrusage(resource.RUSAGE_SELF)
            start = time.perf_counter()
            await anyio.sleep(seconds)
            elapsed = time.perf_counter() - start
            usage = resource.getrusage(resource.RUSAGE_SELF)
            missed = sum(g.missed for g in poller.groups.values()) - missed0
            done = scans - scans0
            tg.cancel_scope.cancel()
    cpu = (usage.ru_utime - usage0.ru_utime) + (usage.ru_stime - usage0.ru_stime)
    print(
        f"  {len(ports)} PLCs via Pool+Poller, {interval * 1000:.0f} ms interval "
        f"({len(ports) / interval:.0f} scans/s asked): {done / elapsed:.0f} reads/s, "
        f"CPU {100 * cpu / elapsed:.0f} % of one core ({1e6 * cpu / max(done, 1):.0f} µs per "
        f"scan), {missed} scans missed"
    )


async def main(seconds: float) -> None:
    with responders(1, 19700) as (port,):
        await full_dm(port)
    with simulator() as url:
        await tag_scan(url, seconds)
    with responders(200, 19800) as ports:
        for interval in (0.2, 0.1, 0.05):
            await many_plcs(ports, seconds, interval)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--uvloop", action="store_true")
    args = parser.parse_args()
    backend_options = {"use_uvloop": True} if args.uvloop else {}
    anyio.run(main, args.seconds, backend_options=backend_options)
