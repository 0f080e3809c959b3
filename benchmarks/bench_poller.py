"""The Poller's CPU per scan against issue #25's hand-written daemon, source trees compared in
one run: interleaved rounds over the same C responders, medians with the range.

Each round runs, one after another, ``bench_api.hand_written_daemon`` and ``bench_api.poll``
(a Pool and a Poller, 20 tags per PLC, uvloop) once per tree, each in a fresh process whose
``PYTHONPATH`` is that tree's ``src`` (the harness is this tree's ``bench_api.py``). A row per
tree: CPU per scan (``getrusage``, user + system, over ``--seconds`` once every group has
scanned three times), its ratio to the daemon's in the same round, missed scans, share of
one core; and each tree's ratio to the first.

    git worktree add /tmp/base <commit>
    python benchmarks/bench_poller.py --trees base=/tmp/base/src,new=src --plcs 100 --interval 0.05
    python benchmarks/bench_poller.py --plcs 1000 --interval 0.1 --rounds 3 --seconds 3

Wall clock: read the ratios (taken within each round) and the load average printed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

INNER = r"""
import json, sys
import anyio
sys.path.insert(0, sys.argv[5])
from bench_api import hand_written_daemon, poll, uvloop_options
ports, kind = json.loads(sys.argv[1]), sys.argv[2]
seconds, interval = float(sys.argv[3]), float(sys.argv[4])
options = uvloop_options("uvloop")
if kind == "daemon":
    print(anyio.run(hand_written_daemon, ports, interval, seconds, backend_options=options), 0)
else:  # the pool's timeout at 5 s: opening 1,000 sessions on a loaded machine
    done, missed, used = anyio.run(poll, ports, interval, seconds, 5.0, backend_options=options)
    print(used / max(done, 1), missed)
"""


def run(kind: str, src: str, ports: list[int], seconds: float, interval: float) -> list[float]:
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = os.path.abspath(src)
    args = [json.dumps(ports), kind, str(seconds), str(interval), str(HERE)]
    out = subprocess.run(
        [sys.executable, "-c", INNER, *args], env=env, capture_output=True, text=True
    )
    if out.returncode:
        raise SystemExit(f"{kind} ({src or 'this tree'}) failed:\n{out.stderr[-3000:]}")
    return [float(x) for x in out.stdout.split()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trees", default="", help="name=SRC,... (default: this tree)")
    parser.add_argument("--plcs", type=int, default=100)
    parser.add_argument("--interval", type=float, default=0.05)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=2.0, help="seconds measured per case")
    args = parser.parse_args()
    trees = dict(t.split("=", 1) for t in args.trees.split(",") if t) or {"this": ""}
    from bench_api import responders

    daemon: list[float] = []
    cpu: dict[str, list[float]] = {name: [] for name in trees}
    missed: dict[str, list[int]] = {name: [] for name in trees}
    print(f"{args.plcs} PLCs x 20 tags every {args.interval * 1e3:g} ms, {args.rounds} rounds")
    with responders(args.plcs) as ports:
        for i in range(args.rounds):
            load = os.getloadavg()[0]
            daemon.append(run("daemon", "", ports, args.seconds, args.interval)[0])
            line = [f"round {i + 1} (load {load:.1f}): daemon {daemon[-1] * 1e6:.1f} µs"]
            for name, src in trees.items():
                per, lost = run("poll", src, ports, args.seconds, args.interval)
                cpu[name].append(per)
                missed[name].append(int(lost))
                line.append(f"{name} {per * 1e6:.1f} µs ({int(lost)} missed)")
            print(", ".join(line), flush=True)
    print(f"load average at the end: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")

    def row(name: str, values: list[float]) -> None:
        spread = f"{min(values):.2f}-{max(values):.2f}"
        print(f"{name:<44} {statistics.median(values):9.2f} {spread:>15}")

    print(f"\n{'row':<44} {'median':>9} {'min-max':>15}")
    row("daemon: CPU per scan (µs)", [d * 1e6 for d in daemon])
    first = next(iter(trees))
    scans_per_s = args.plcs / args.interval
    for name in trees:
        row(f"{name}: CPU per scan (µs)", [c * 1e6 for c in cpu[name]])
        row(f"{name}: / daemon (≤ 1.0)", [c / d for c, d in zip(cpu[name], daemon, strict=True)])
        row(
            f"{name}: % of a core (per scan x scan rate)",
            [100 * c * scans_per_s for c in cpu[name]],
        )
        row(f"{name}: missed scans (= 0)", [float(m) for m in missed[name]])
        if name != first:
            ratios = [c / b for c, b in zip(cpu[name], cpu[first], strict=True)]
            row(f"{name}: / {first}", ratios)


if __name__ == "__main__":
    main()
