"""Frames per second the virtual PLC serves on one core, measured with the C load generator.

Starts ``aiofins simulate --udp 127.0.0.1:0 --tcp 127.0.0.1:0`` (pinned to one CPU), then runs
``fins_pingpong`` (../shared/tools/perf) against it: sequential 1-word reads and 50 in flight,
over UDP and FINS/TCP. Prints a table.

    python benchmarks/bench_simulator.py [--seconds 3]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

PERF_TOOLS = Path(
    os.environ.get("AIOFINS_PERF_TOOLS", Path(__file__).resolve().parents[2] / "shared/tools/perf")
)


def build_tools() -> Path:
    subprocess.run(["make", "-s", "-C", str(PERF_TOOLS)], check=True)
    return PERF_TOOLS / "bin" / "fins_pingpong"


def start_simulator(cpu: int) -> tuple[subprocess.Popen[str], int, int]:
    cmd = [
        sys.executable,
        "-m",
        "aiofins.cli",
        "simulate",
        "--udp",
        "127.0.0.1:0",
        "--tcp",
        "127.0.0.1:0",
        "--mode",
        "run",
    ]
    if hasattr(os, "sched_setaffinity"):
        cmd = ["taskset", "-c", str(cpu), *cmd]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    ports: dict[str, int] = {}
    for line in proc.stdout:
        m = re.match(r"listening on (udp|tcp)://127\.0\.0\.1:(\d+)", line)
        if m:
            ports[m.group(1)] = int(m.group(2))
        if len(ports) == 2:
            break
    return proc, ports["udp"], ports["tcp"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    pingpong = build_tools()
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
    sim_cpu, client_cpu = cpus[0], cpus[-1]
    proc, udp_port, tcp_port = start_simulator(sim_cpu)
    try:
        print(f"{'case':<28} {'req/s':>10} {'p50 us':>8} {'p99 us':>8}")
        for name, port, extra in (
            ("UDP sequential", udp_port, []),
            ("UDP 50 in flight", udp_port, ["-w", "50"]),
            ("TCP sequential", tcp_port, ["-t"]),
            ("TCP 50 in flight", tcp_port, ["-t", "-w", "50"]),
            ("UDP 999-word reads", udp_port, ["-c", "999"]),
        ):
            cmd = [str(pingpong), "-p", str(port), "-d", str(args.seconds), *extra]
            if client_cpu != sim_cpu:
                cmd = ["taskset", "-c", str(client_cpu), *cmd]
            out = subprocess.run(cmd, capture_output=True, text=True, check=False).stdout
            rate = re.search(r"req_s=([\d.]+)", out)
            p50 = re.search(r"p50_us=([\d.]+)", out)
            p99 = re.search(r"p99_us=([\d.]+)", out)
            print(
                f"{name:<28} {float(rate.group(1)) if rate else float('nan'):>10.0f} "
                f"{p50.group(1) if p50 else '-':>8} {p99.group(1) if p99 else '-':>8}"
            )
    finally:
        proc.terminate()
        proc.wait(timeout=10)


if __name__ == "__main__":
    main()
