"""Set the PLC's clock to this computer's time when they differ by more than a few seconds.

A PLC's clock drifts and knows nothing of daylight saving time; its error log and any time
stamps the program writes are only as good as the clock. Run this from cron (or a systemd
timer) on a computer whose own clock NTP keeps right. ``--dry-run`` only reports the drift.

    python examples/sync_clock.py --dry-run
    PLC_URL=udp://192.168.250.1 python examples/sync_clock.py --max-drift 2
"""

from __future__ import annotations

import argparse
import os
from datetime import datetime

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")


async def sync(max_drift: float, dry_run: bool) -> None:
    async with aiofins.connect(PLC_URL, timeout=2.0) as plc:
        clock = await plc.clock_read()
        drift = (clock.time - datetime.now()).total_seconds()
        print(f"PLC clock {clock.time:%Y-%m-%d %H:%M:%S} ({clock.day_name}), drift {drift:+.0f} s")
        if abs(drift) <= max_drift:
            print("within the tolerance: left alone")
        elif dry_run:
            print(f"more than {max_drift:g} s off: would set it (--dry-run)")
        else:
            now = datetime.now()
            await plc.clock_write(now, (now.weekday() + 1) % 7)  # FINS: 0 is Sunday
            print(f"set to {now:%Y-%m-%d %H:%M:%S}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-drift", type=float, default=2.0, help="seconds (default 2)")
    parser.add_argument("--dry-run", action="store_true", help="report, do not set the clock")
    args = parser.parse_args()
    anyio.run(sync, args.max_drift, args.dry_run)
