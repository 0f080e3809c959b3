"""Log tags to a CSV file: one row per scan, a time stamp and one column per tag.

A tag whose read failed (a timeout, a refused address) is logged as an empty cell, and the
scan goes on: a spreadsheet or pandas reads the gaps as missing values.

    python examples/log_to_csv.py --samples 10                 # 10 rows on stdout
    python examples/log_to_csv.py --interval 5 --output line1.csv   # until Ctrl-C
    PLC_URL=udp://192.168.250.1 python examples/log_to_csv.py temperature=D200:float32
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
from contextlib import nullcontext, suppress
from datetime import datetime

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")

DEFAULT_TAGS = ["temperature=D100:float32", "pressure=D102:int32", "running=CIO 0.00"]


async def log(tags: dict[str, str], interval: float, samples: int, output: str | None) -> None:
    with open(output, "a", newline="") if output else nullcontext(sys.stdout) as file:
        out = csv.writer(file)
        if not output or file.tell() == 0:  # a new file (or stdout) gets the header
            out.writerow(["time", *tags])
        async with aiofins.Pool(timeout=1.0) as pool, aiofins.Poller(pool) as poller:
            poller.add_group("csv", PLC_URL, tags, interval=interval)
            async for snap in poller:
                stamp = datetime.fromtimestamp(snap.timestamp).isoformat(timespec="milliseconds")
                row = [
                    r.value if r.quality is aiofins.Quality.GOOD else ""
                    for r in snap.readings.values()
                ]
                out.writerow([stamp, *row])
                file.flush()
                if samples and snap.scan >= samples:
                    return


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tags", nargs="*", default=DEFAULT_TAGS, help="NAME=ADDRESS[:TYPE]")
    parser.add_argument("--interval", type=float, default=1.0, help="seconds between rows")
    parser.add_argument("--samples", type=int, default=0, help="rows to log (0: until Ctrl-C)")
    parser.add_argument("--output", help="CSV file to append to (default: stdout)")
    args = parser.parse_args()
    tags = {name: spec or name for name, _, spec in (t.partition("=") for t in args.tags)}
    with suppress(KeyboardInterrupt):
        anyio.run(log, tags, args.interval, args.samples, args.output)
