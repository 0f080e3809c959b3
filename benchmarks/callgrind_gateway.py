"""Instructions per published scan of one gateway process (callgrind), for source trees
compared in one run: counts that a busy machine does not stretch.

One gateway over N C responders (../shared/tools/perf/fins_responder.c) x 20 tags every 2 s,
QoS 0, into a local Mosquitto; valgrind's callgrind counts the gateway's instructions (user
space: not the kernel's share) from ``--warmup`` seconds after start for ``--seconds``;
divided by the scans it published meanwhile (its own /metrics, scraped just outside the
window).

    git worktree add /tmp/base <commit>
    python benchmarks/callgrind_gateway.py --trees base=/tmp/base/src,new=src [--rounds 2]

Needs gcc, mosquitto, valgrind and callgrind_control.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from bench_gateway import PERF_TOOLS, free_port, wait_port

KINDS = ["uint16", "int16", "float32", "int32"]  # a word apart: one 0101 frame


def published(port: int) -> float:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=60) as response:
        text = response.read().decode()
    pattern = r"^aiofins_gateway_published_messages_total\{.*\} ([0-9.e+]+)$"
    return sum(float(m.group(1)) for m in re.finditer(pattern, text, re.MULTILINE))


def measure(
    src: str, tmp: Path, responder: Path, plcs: int, warmup: float, seconds: float
) -> float:
    """Instructions per published scan of one gateway of the aiofins in ``src``."""
    broker = free_port()
    (tmp / "mosquitto.conf").write_text(f"listener {broker} 127.0.0.1\nallow_anonymous true\n")
    procs = [
        subprocess.Popen(
            ["mosquitto", "-c", str(tmp / "mosquitto.conf")], stderr=subprocess.DEVNULL
        )
    ]
    ports = [free_port() for _ in range(plcs)]
    procs += [
        subprocess.Popen([str(responder), "-p", str(p), "-q"], stderr=subprocess.DEVNULL)
        for p in ports
    ]
    http = free_port()
    tags = ", ".join(f't{i} = "D{i * 2}:{KINDS[i % len(KINDS)]}"' for i in range(20))
    table = "".join(
        f'[[plcs]]\nname = "plc{i:03}"\nurl = "udp://127.0.0.1:{p}"\n' for i, p in enumerate(ports)
    )
    cfg = tmp / "gateway.toml"
    cfg.write_text(
        f'[gateway]\nname = "cg"\n[mqtt]\nport = {broker}\n[http]\nport = {http}\n'
        f'[connect]\ntimeout = 5.0\n[[groups]]\nname = "g"\ninterval = 2.0\nbuffer = 10\n'
        f"tags = {{ {tags} }}\n{table}"
    )
    try:
        wait_port(broker, procs[0], "mosquitto")
        for proc, port in zip(procs[1:], ports, strict=True):
            wait_port(port, proc, f"responder on {port}")
    except BaseException:
        stop(procs)
        raise
    out = tmp / "callgrind.out"
    gateway = subprocess.Popen(
        [
            "valgrind",
            "--tool=callgrind",
            "--instr-atstart=no",
            f"--callgrind-out-file={out}",
            sys.executable,
            "-m",
            "aiofins.cli",
            "gateway",
            str(cfg),
            "--log-level",
            "ERROR",
        ],
        env={**os.environ, "PYTHONPATH": str(Path(src).resolve())},
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_port(http, gateway, "gateway (under valgrind)")
        time.sleep(warmup)
        control = ["callgrind_control", "-i"]
        # The scrapes stay outside the window (a scrape's cost is no scan's, and differs
        # from tree to tree); the scans published between a scrape and a switch are few.
        before = published(http)
        subprocess.run([*control, "on", str(gateway.pid)], check=True, capture_output=True)
        time.sleep(seconds)
        subprocess.run([*control, "off", str(gateway.pid)], check=True, capture_output=True)
        after = published(http)
    finally:
        gateway.send_signal(signal.SIGINT)
        try:
            gateway.wait(timeout=300)
        except subprocess.TimeoutExpired:
            gateway.kill()
            gateway.wait()
        stop(procs)
    total = 0
    for path in tmp.glob("callgrind.out*"):
        for line in path.read_text(errors="replace").splitlines():
            if line.startswith(("summary:", "totals:")):
                total = max(total, int(line.split()[1]))
        path.unlink()
    return total / (after - before)


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    for proc in procs:
        proc.terminate()
    for proc in procs:
        proc.wait(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", required=True, help="NAME=SRC_DIR,... (a tree's src)")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--plcs", type=int, default=20)
    parser.add_argument("--warmup", type=float, default=15.0)
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    for tool in ("gcc", "mosquitto", "valgrind", "callgrind_control"):
        if shutil.which(tool) is None:
            raise SystemExit(f"{tool} is needed")
    trees = [(n, s) for n, _, s in (t.partition("=") for t in args.trees.split(",") if t)]
    results: dict[str, list[float]] = {name: [] for name, _ in trees}
    with tempfile.TemporaryDirectory(prefix="aiofins-cg-gw-") as name:
        tmp = Path(name)
        responder = tmp / "fins_responder"
        source = str(PERF_TOOLS / "fins_responder.c")
        subprocess.run(["gcc", "-O2", "-o", str(responder), source], check=True)
        for round_ in range(args.rounds):
            shift = round_ % len(trees)
            for tree, src in trees[shift:] + trees[:shift]:
                value = measure(src, tmp, responder, args.plcs, args.warmup, args.seconds)
                results[tree].append(value)
                print(f"round {round_ + 1} {tree}: {value / 1e3:.0f}k instructions per scan")
    first = statistics.median(results[trees[0][0]])
    for tree, values in results.items():
        median = statistics.median(values)
        runs = ", ".join(f"{v / 1e3:.0f}k" for v in values)
        print(f"{tree}: median {median / 1e3:.0f}k ({runs}), {median / first:.3f} x {trees[0][0]}")


if __name__ == "__main__":
    main()
