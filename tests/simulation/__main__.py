"""``python -m tests.simulation --seeds N --steps M``: run seeds, print a reproducer per
violation (``--seed S`` replays one; ``--schedule`` replays a printed schedule)."""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time

from .world import EXPOSED, UNFIXED, Episode, run, suspect


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.simulation")
    parser.add_argument("--seeds", type=int, default=100, help="how many seeds (from --first)")
    parser.add_argument("--first", type=int, default=0, help="the first seed")
    parser.add_argument("--seed", type=int, help="run this one seed")
    parser.add_argument("--steps", type=int, default=2000, help="steps per seed")
    parser.add_argument("--schedule", help="replay this fault schedule (as printed)")
    parser.add_argument("--stop", action="store_true", help="stop at the first violation")
    parser.add_argument("--quiet", action="store_true", help="print only violations and totals")
    parser.add_argument("--defect", type=int, help="run the world of issue 22's defect N")
    parser.add_argument("--unfixed", action="store_true", help="run the unfixed families' worlds")
    parser.add_argument(
        "--regressions", action="store_true", help="run the pinned worlds of fixed families"
    )
    parser.add_argument("--log", action="store_true", help="show the library's warnings")
    args = parser.parse_args(argv)
    if not args.log:
        logging.disable(logging.CRITICAL)
    if args.defect is not None:
        from .scenarios import DEFECTS, run_defect

        print(f"defect {args.defect}: {DEFECTS[args.defect][0]}")
        found = run_defect(args.defect)
        print(found.reproducer() if found.violation else "no violation")
        return 1 if found.violation else 0
    if args.unfixed:
        from .scenarios import UNFIXED_WORLDS, run_unfixed

        shown = 0
        for kind, (what, *_) in UNFIXED_WORLDS.items():
            print(f"{kind}: {what}")
            for result in run_unfixed(kind):
                shown += result.violation is not None
                print(result.reproducer() if result.violation else "  no violation")
        return 1 if shown else 0
    if args.regressions:
        from .scenarios import REGRESSIONS, run_regression

        shown = 0
        for name, (what, *_) in REGRESSIONS.items():
            print(f"{name}: {what}")
            result = run_regression(name)
            shown += result.violation is not None
            print(result.reproducer() if result.violation else "  no violation")
        return 1 if shown else 0
    seeds = [args.seed] if args.seed is not None else range(args.first, args.first + args.seeds)
    schedule = (
        [Episode.parse(e) for e in args.schedule.split(",") if e and e != "-"]
        if args.schedule is not None
        else None
    )
    started = time.perf_counter()
    steps = violations = 0
    kinds: dict[str, int] = {}
    for seed in seeds:
        result = run(seed, args.steps, schedule)
        steps += result.steps
        if result.violation is not None:
            violations += 1
            line = result.reproducer()
            kind = suspect(result)
            kinds[kind] = kinds.get(kind, 0) + 1
            print(f"{line}  [{kind}]", flush=True)
            if args.stop:
                break
        elif not args.quiet:
            print(f"seed {seed}: {result.steps} steps, {result.ops} ops, ok", flush=True)
    elapsed = time.perf_counter() - started
    print(
        f"{len(seeds)} seeds, {steps} steps, {violations} violations, {elapsed:.1f} s",
        flush=True,
    )
    for kind, count in sorted(kinds.items()):
        allowed = " (exposed)" if kind in EXPOSED else " (unfixed)" if kind in UNFIXED else ""
        rate = count / steps * 1e6 if steps else 0.0
        print(f"  {count} x {kind}{allowed}: {rate:.2f} per million steps")
    return 1 if violations else 0


if __name__ == "__main__":
    if os.environ.get("PYTHONHASHSEED") != "0":  # set iteration order as in every replay
        os.environ["PYTHONHASHSEED"] = "0"
        os.execv(sys.executable, [sys.executable, "-m", "tests.simulation", *sys.argv[1:]])
    sys.exit(main())
