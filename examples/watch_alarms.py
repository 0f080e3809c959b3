"""Watch alarm bits and print each alarm as it is raised and cleared, with its time.

The alarm list maps work-area bits (set by the PLC program) to what an operator reads. Only
changes are printed: the Poller's ``changes_only`` hands over the bits that changed since the
scan before (the first scan: all of them, so alarms already active are printed too).
If the PLC stops answering, that is printed once, and again when it is back.

    python examples/watch_alarms.py                     # until Ctrl-C
    PLC_URL=udp://192.168.250.1 python examples/watch_alarms.py --interval 0.2
"""

from __future__ import annotations

import argparse
import os
from contextlib import suppress
from datetime import datetime

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")

ALARMS = {
    "W0.00": "high temperature in oven 1",
    "W0.01": "low hydraulic pressure",
    "W0.02": "conveyor 2 jammed",
    "W0.03": "emergency stop pressed",
    "W0.04": "door open in cell 3",
}


async def watch(interval: float) -> None:
    tags = {address: address for address in ALARMS}  # tag name: the bit's address
    async with (
        aiofins.Pool(timeout=1.0, read_only=True) as pool,
        aiofins.Poller(pool, changes_only=True) as poller,
    ):
        poller.add_group("alarms", PLC_URL, tags, interval=interval)
        print(f"watching {len(ALARMS)} alarms on {PLC_URL}", flush=True)
        reachable = True
        async for snap in poller:
            when = datetime.fromtimestamp(snap.timestamp).strftime("%Y-%m-%d %H:%M:%S")
            if (snap.error is None) != reachable:
                reachable = snap.error is None
                print(f"{when}  {'PLC answers again' if reachable else snap.error}", flush=True)
            for address, reading in snap.readings.items():
                if reading.quality is aiofins.Quality.GOOD:
                    state = "RAISED " if reading.value else "cleared"
                    if reading.value or snap.scan > 1:  # at start: only the active ones
                        print(f"{when}  {state}  {ALARMS[address]} ({address})", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--interval", type=float, default=0.5, help="seconds between scans")
    args = parser.parse_args()
    with suppress(KeyboardInterrupt):
        anyio.run(watch, args.interval)
