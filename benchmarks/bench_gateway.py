"""The gateway under plant-like load: N PLC endpoints x T tags every second into Mosquitto.

Each PLC endpoint is one C responder process (../shared/tools/perf/fins_responder.c, built
into a temporary directory), the broker a local ``mosquitto``, and ``mosquitto_sub`` records
every scan message with its arrival time. For one gateway, then for two shards of the same
configuration, it reports after a warm-up:

* missed scans (the poller's count of scan times skipped) and failed scans;
* CPU seconds of each gateway process per published scan message;
* scan-to-delivery latency p50/p99 (the scan's timestamp to ``mosquitto_sub`` receiving it,
  broker included).
* the event loop's lag in the window (``aiofins_gateway_loop_lag_seconds``, a probe every
  0.25 s: how many were late by more than 0.1, 0.5 and 1 s; trees without it say n/a).

``/metrics`` is scraped at the window's start and end; ``--scrape-every 5`` also scrapes it
inside the window, as Prometheus would (a scrape that holds the loop shows as misses).

    python benchmarks/bench_gateway.py [--plcs 1000] [--tags 20] [--seconds 30] [--warmup 10]

To compare source trees in the same run (same responders and broker, rounds interleaved),
name each tree's ``src`` directory; medians and the ratio to the first tree are printed:

    git worktree add /tmp/base <commit>
    python benchmarks/bench_gateway.py --shards 1 --rounds 5 --trees base=/tmp/base/src,new=src

Needs gcc, mosquitto and mosquitto_sub (Debian: mosquitto mosquitto-clients).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

PERF_TOOLS = Path(
    os.environ.get("AIOFINS_PERF_TOOLS", Path(__file__).resolve().parents[2] / "shared/tools/perf")
)
TICKS = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    """A port free for TCP and for UDP (a responder binds both: a port only TCP-free made
    one of ~250 responders fail on a machine busy with UDP tests)."""
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
                try:
                    u.bind(("127.0.0.1", port))
                except OSError:
                    continue
            return port


def wait_port(port: int, proc: subprocess.Popen[bytes], what: str) -> None:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"{what} exited ({proc.returncode})")
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            time.sleep(0.05)
    raise SystemExit(f"{what} did not listen on {port}")


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime


def metrics(port: int) -> dict[str, float]:
    """Sum of each aiofins_gateway_* sample over its labels; the loop lag histogram's
    buckets by their bound (``lag<=0.1``; trees that have it)."""
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=60) as response:
        text = response.read().decode()
    out: dict[str, float] = {}
    for line in text.splitlines():
        m = re.match(r"^(aiofins_gateway_\w+?)(?:\{.*\})? ([0-9.e+-]+)$", line)
        if m:
            out[m.group(1)] = out.get(m.group(1), 0.0) + float(m.group(2))
        lag = re.match(r'^aiofins_gateway_loop_lag_seconds_bucket\{le="([^"]+)"\} (\S+)$', line)
        if lag:
            out[f"lag<={lag.group(1)}"] = float(lag.group(2))
    return out


def lag_summary(m0: dict[str, float], m1: dict[str, float]) -> str:
    """The loop lag probes of the window: how many, and how many were late by more than
    0.1, 0.5 and 1 s ("n/a" for a tree without the histogram)."""
    if "lag<=+Inf" not in m1:
        return "n/a"
    total = m1["lag<=+Inf"] - m0.get("lag<=+Inf", 0.0)

    def over(bound: str) -> float:
        return total - (m1[f"lag<={bound}"] - m0.get(f"lag<={bound}", 0.0))

    worst = next(
        (
            b
            for b in sorted((k[5:] for k in m1 if k.startswith("lag<=")), key=float)
            if m1[f"lag<={b}"] - m0.get(f"lag<={b}", 0.0) == total
        ),
        "+Inf",
    )
    return (
        f"{total:.0f} probes, late > 0.1 s {over('0.1'):.0f}, > 0.5 s {over('0.5'):.0f}, "
        f"> 1 s {over('1.0'):.0f}, all <= {worst} s"
    )


def config(broker: int, http_ports: list[int], ports: list[int], tags: int) -> str:
    kinds = ["uint16", "int16", "float32", "int32"]  # a word apart: one 0101 frame
    tag_table = ", ".join(f't{i} = "D{i * 2}:{kinds[i % len(kinds)]}"' for i in range(tags))
    plcs = "".join(
        f'[[plcs]]\nname = "plc{i:04}"\nurl = "udp://127.0.0.1:{port}"\n'
        for i, port in enumerate(ports)
    )
    return (
        f'[gateway]\nname = "bench"\n[mqtt]\nport = {broker}\n'
        f"[http]\nport = {http_ports[0]}\n[connect]\ntimeout = 1.0\n"
        f'[[groups]]\nname = "g"\ninterval = 1.0\nbuffer = 10\ntags = {{ {tag_table} }}\n{plcs}'
    )


def run_case(
    shards: int,
    cfg: Path,
    broker: int,
    seconds: float,
    warmup: float,
    tmp: Path,
    src: str | None = None,
    scrape_every: float = 0.0,
) -> dict[str, object]:
    """One case: ``shards`` gateway processes (of the aiofins in ``src``, a source tree's
    ``src`` directory, if given) for ``warmup`` + ``seconds``."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(Path(src).resolve())
    http_ports = [free_port() for _ in range(shards)]
    text = cfg.read_text()
    procs: list[subprocess.Popen[bytes]] = []
    for i in range(shards):
        path = tmp / f"gateway{i}.toml"
        path.write_text(re.sub(r"\[http\]\nport = \d+", f"[http]\nport = {http_ports[i]}", text))
        # ERROR: what "--log-level WARNING" gave before the CLI's one logging set-up (a
        # WARNING per missed scan is formatted now; the benchmark measures the gateway).
        args = [sys.executable, "-m", "aiofins.cli", "gateway", str(path), "--log-level", "ERROR"]
        if shards > 1:
            args += ["--shard", f"{i}/{shards}"]
        procs.append(subprocess.Popen(args, stdout=subprocess.DEVNULL, env=env))
    record = tmp / f"sub{shards}.txt"
    with record.open("w") as out:
        sub = subprocess.Popen(
            ["mosquitto_sub", "-p", str(broker), "-t", "fins/+/g", "-F", "%U %p"], stdout=out
        )
        try:
            for proc, port in zip(procs, http_ports, strict=True):
                wait_port(port, proc, "gateway")
            time.sleep(warmup)
            start = time.time()
            cpu0 = [cpu_seconds(p.pid) for p in procs]
            m0 = [metrics(port) for port in http_ports]
            scrapes = 0
            while scrape_every and time.time() + scrape_every < start + seconds:
                time.sleep(scrape_every)
                for port in http_ports:  # as Prometheus would, inside the window
                    metrics(port)
                scrapes += 1
            time.sleep(max(0.0, start + seconds - time.time()))
            end = time.time()
            cpu1 = [cpu_seconds(p.pid) for p in procs]
            m1 = [metrics(port) for port in http_ports]
        finally:
            for proc in procs:
                proc.send_signal(signal.SIGINT)
            for proc in procs:
                proc.wait(timeout=60)
            sub.terminate()
            sub.wait(timeout=10)

    def delta(name: str) -> float:
        return sum(b.get(name, 0.0) - a.get(name, 0.0) for a, b in zip(m0, m1, strict=True))

    latencies: list[float] = []
    for line in record.read_text().splitlines():
        arrived, _, payload = line.partition(" ")
        try:
            scan_time = json.loads(payload)["timestamp"]
        except ValueError:
            continue
        if start <= scan_time < end:
            latencies.append(float(arrived) - scan_time)
    latencies.sort()
    published = delta("aiofins_gateway_published_messages_total")
    cpu = [b - a for a, b in zip(cpu0, cpu1, strict=True)]
    return {
        "shards": shards,
        "scans": delta("aiofins_gateway_scans_total"),
        "missed": delta("aiofins_gateway_missed_scans_total"),
        "failed": delta("aiofins_gateway_scan_errors_total"),
        "published": published,
        "dropped": delta("aiofins_gateway_dropped_messages_total"),
        "received": len(latencies),
        "cpu_per_process": [c / seconds for c in cpu],
        "cpu_us_per_scan": 1e6 * sum(cpu) / published if published else float("nan"),
        "p50_ms": 1e3 * statistics.median(latencies) if latencies else float("nan"),
        "p99_ms": 1e3 * latencies[int(0.99 * (len(latencies) - 1))] if latencies else float("nan"),
        "scrapes": scrapes,
        "loop_lag": "; ".join(lag_summary(a, b) for a, b in zip(m0, m1, strict=True)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plcs", type=int, default=1000)
    parser.add_argument("--tags", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup", type=float, default=10.0)
    parser.add_argument("--shards", default="1,2", help="the cases to run (default 1,2)")
    parser.add_argument(
        "--trees",
        default="",
        help="NAME=SRC_DIR,... source trees to compare, rounds interleaved (default: this one)",
    )
    parser.add_argument("--rounds", type=int, default=1, help="rounds of every case and tree")
    parser.add_argument(
        "--scrape-every",
        type=float,
        default=0.0,
        help="also scrape /metrics every S seconds inside the window (default: only at its "
        "start and end)",
    )
    args = parser.parse_args()
    for tool in ("gcc", "mosquitto", "mosquitto_sub"):
        if shutil.which(tool) is None:
            raise SystemExit(f"{tool} is needed")
    with tempfile.TemporaryDirectory(prefix="aiofins-bench-gw-") as name:
        tmp = Path(name)
        responder = tmp / "fins_responder"
        subprocess.run(
            ["gcc", "-O2", "-o", str(responder), str(PERF_TOOLS / "fins_responder.c")], check=True
        )
        broker_port = free_port()
        (tmp / "mosquitto.conf").write_text(
            f"listener {broker_port} 127.0.0.1\nallow_anonymous true\nmax_queued_messages 100000\n"
            "set_tcp_nodelay true\n"
        )
        broker = subprocess.Popen(
            ["mosquitto", "-c", str(tmp / "mosquitto.conf")], stderr=subprocess.DEVNULL
        )
        responders: list[subprocess.Popen[bytes]] = []
        try:
            wait_port(broker_port, broker, "mosquitto")
            ports: list[int] = []
            while len(ports) < args.plcs:
                port = free_port()
                if port in ports:
                    continue
                command = [str(responder), "-p", str(port), "-q"]
                responders.append(subprocess.Popen(command, stderr=subprocess.DEVNULL))
                ports.append(port)
            for proc, port in zip(responders, ports, strict=True):
                wait_port(port, proc, f"responder on {port}")
            cfg = tmp / "gateway.toml"
            cfg.write_text(config(broker_port, [0], ports, args.tags))
            print(
                f"{args.plcs} PLC endpoints x {args.tags} tags every 1 s, "
                f"{args.seconds:g} s measured after {args.warmup:g} s warm-up"
            )
            mosquitto_cpu0 = cpu_seconds(broker.pid)
            trees: list[tuple[str, str | None]] = [
                (name, src)
                for name, _, src in (t.partition("=") for t in args.trees.split(",") if t)
            ] or [("", None)]
            cpu_per_scan: dict[tuple[int, str], list[float]] = {}
            missed: dict[tuple[int, str], list[float]] = {}
            for round_ in range(args.rounds):
                for shards in (int(s) for s in args.shards.split(",")):
                    # Each round starts with the next tree: none always runs last (the
                    # machine's load drifts within a round).
                    shift = round_ % len(trees)
                    for name, src in trees[shift:] + trees[:shift]:
                        r = run_case(
                            shards,
                            cfg,
                            broker_port,
                            args.seconds,
                            args.warmup,
                            tmp,
                            src,
                            args.scrape_every,
                        )
                        cpu_per_scan.setdefault((shards, name), []).append(
                            float(r["cpu_us_per_scan"])  # type: ignore[arg-type]
                        )
                        missed.setdefault((shards, name), []).append(float(r["missed"]))  # type: ignore[arg-type]
                        label = f"round {round_ + 1} {name}: " if name else ""
                        report(label, shards, r)
            if len(trees) > 1 or args.rounds > 1:
                print(f"load average at the end: {os.getloadavg()}")
                for (shards, name), values in cpu_per_scan.items():
                    first = statistics.median(cpu_per_scan[(shards, trees[0][0])])
                    median = statistics.median(values)
                    print(
                        f"{shards} gateway(s) {name or 'this tree'}: CPU per published scan "
                        f"median {median:.1f} us (runs {', '.join(f'{v:.0f}' for v in values)};"
                        f" min-max {min(values) / median - 1:+.0%}..{max(values) / median - 1:+.0%}"
                        f"), {median / first:.3f} x {trees[0][0] or 'the first'}; missed "
                        f"{', '.join(f'{v:.0f}' for v in missed[(shards, name)])}"
                    )
            print(f"mosquitto CPU over all runs: {cpu_seconds(broker.pid) - mosquitto_cpu0:.1f} s")
        finally:
            for proc in responders:
                proc.terminate()
            for proc in responders:
                proc.wait(timeout=10)
            broker.terminate()
            broker.wait(timeout=10)


def report(label: str, shards: int, r: dict[str, object]) -> None:
    per_process = ", ".join(f"{c:.0%}" for c in r["cpu_per_process"])  # type: ignore[attr-defined]
    print(
        f"{label}{shards} gateway(s): scans {r['scans']:.0f}, missed {r['missed']:.0f}, "
        f"failed {r['failed']:.0f}, published {r['published']:.0f}, "
        f"dropped {r['dropped']:.0f}, received {r['received']}; "
        f"CPU per process {per_process} of a core, "
        f"{r['cpu_us_per_scan']:.0f} us per published scan; "
        f"scan-to-delivery p50 {r['p50_ms']:.1f} ms, p99 {r['p99_ms']:.1f} ms; "
        f"{r['scrapes']} scrapes in the window; loop lag: {r['loop_lag']}; "
        f"load average {os.getloadavg()[0]:.1f}",
        flush=True,
    )


if __name__ == "__main__":
    main()
