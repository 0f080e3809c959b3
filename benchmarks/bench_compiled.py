"""The pure and the compiled package in the same run: bench_targets.py's rows, rounds interleaved.

Each round runs ``bench_targets.py --rounds 1`` once with each interpreter (one from a venv
with the pure package, one from a venv with the compiled wheel, docs/packaging.md), the
order swapped every round so neither always runs first; every row's value is read from its
table. The result gives each row's median and range (min-max) per variant and the ratio of
the medians (compiled / pure), and the load average before and after.

    python benchmarks/bench_compiled.py --pure .venv/bin/python \\
        --compiled .venv-compiled/bin/python [--rounds 5] [--seconds 1] [--skip poll100]

(``poll1000`` is always skipped: it runs once, not in rounds.)
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: bench_targets.py's table: the row's name is its first 50 characters, the value follows.
NAME_WIDTH = 50
PROBE = "import aiofins.transport.udp as m; print(m.__file__)"


def load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def variant(python: str) -> str:
    """Where the interpreter imports the package from (an ``.so``: the compiled variant)."""
    out = subprocess.run([python, "-c", PROBE], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def one_round(python: str, seconds: float, skip: str) -> dict[str, float]:
    command = [python, str(HERE / "bench_targets.py"), "--rounds", "1", "--seconds", str(seconds)]
    command += ["--skip", ",".join(filter(None, ["poll1000", skip]))]
    run = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    if run.returncode:
        raise SystemExit(f"{' '.join(command)} failed:\n{run.stdout[-2000:]}{run.stderr[-3000:]}")
    out = run.stdout
    rows: dict[str, float] = {}
    table = out.split("\nrow ", 1)[1].splitlines()[1:]
    for line in table:
        if len(line) > NAME_WIDTH and line[NAME_WIDTH:].split():
            rows[line[:NAME_WIDTH].strip()] = float(line[NAME_WIDTH:].split()[0])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pure", required=True, help="python of a venv with the pure package")
    parser.add_argument("--compiled", required=True, help="python of the compiled one")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--skip", default="", help="passed on to bench_targets.py")
    args = parser.parse_args()
    pythons = {"pure": args.pure, "compiled": args.compiled}
    for name, python in pythons.items():
        print(f"{name}: aiofins.transport.udp from {variant(python)}")
    samples: dict[str, dict[str, list[float]]] = {"pure": {}, "compiled": {}}
    print(f"load average at the start: {load()}", flush=True)
    for i in range(args.rounds):
        order = ["pure", "compiled"] if i % 2 == 0 else ["compiled", "pure"]
        for name in order:
            print(f"round {i + 1} of {args.rounds}: {name} (load {load()})", flush=True)
            for row, value in one_round(pythons[name], args.seconds, args.skip).items():
                samples[name].setdefault(row, []).append(value)
    print(f"load average at the end: {load()}\n")
    head = f"{'row':<50} {'pure':>8} {'(min-max)':>15} {'compiled':>9} {'(min-max)':>15}"
    print(f"{head} {'c/p':>6}  ({args.rounds} rounds each)")
    for row, pure in samples["pure"].items():
        compiled = samples["compiled"].get(row, [])
        if not compiled:
            continue
        p, c = statistics.median(pure), statistics.median(compiled)
        spreads = [f"{min(v):.2f}-{max(v):.2f}" for v in (pure, compiled)]
        ratio = f"{c / p:6.2f}" if p else "     -"
        print(f"{row:<50} {p:8.2f} {spreads[0]:>15} {c:9.2f} {spreads[1]:>15} {ratio}")


if __name__ == "__main__":
    main()
