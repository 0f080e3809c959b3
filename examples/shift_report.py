"""A shift report from a cron job: read the production counters and append one CSV line.

A blocking script (no ``async``): :mod:`aiofins.sync` runs the client's event loop in a
thread of its own. The counters are words and double words a PLC program keeps, read in one
frame; the reject rate is computed here.

    python examples/shift_report.py                      # one line on stdout
    PLC_URL=udp://192.168.250.1 python examples/shift_report.py --output shifts.csv

A crontab line, at each change of shift:

    0 6,14,22 * * *  PLC_URL=udp://192.168.250.1 python shift_report.py -o /srv/shifts.csv
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
from contextlib import nullcontext
from datetime import datetime

import aiofins
import aiofins.sync

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")

COUNTERS = {
    "good": "D300:uint32",  # good parts this shift
    "rejects": "D302:uint32",  # rejected parts
    "downtime_min": "D304:uint16",  # minutes stopped
    "product": "D310:string:12",  # product code running
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", help="CSV file to append to (default: stdout)")
    output = parser.parse_args().output
    try:
        with aiofins.sync.connect(PLC_URL, timeout=2.0, read_only=True) as plc:
            counts = plc.read_tags(COUNTERS)
    except aiofins.FinsError as exc:
        sys.exit(f"{type(exc).__name__}: {exc}")
    good, rejects = int(counts["good"]), int(counts["rejects"])
    rate = rejects / (good + rejects) if good + rejects else 0.0
    row = [f"{datetime.now():%Y-%m-%d %H:%M}", counts["product"], good, rejects]
    row += [counts["downtime_min"], f"{rate:.2%}"]
    with open(output, "a", newline="") if output else nullcontext(sys.stdout) as file:
        csv.writer(file).writerow(row)


if __name__ == "__main__":
    main()
