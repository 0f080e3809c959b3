"""A polling daemon: scan a tag list on several PLCs and print changes as JSON lines.

    python examples/polling_daemon.py                      # the PLC at $PLC_URL
    python examples/polling_daemon.py udp://10.0.0.5 udp://10.0.0.6 --interval 0.5

Each PLC is one scan group with its own interval; a slow or dead PLC does not delay the others
and its tags turn STALE (the last good value kept, with its timestamp; tags never read are
ERROR). Ctrl-C (SIGINT) or SIGTERM (as systemd and Docker stop a service) ends it cleanly:
sessions closed, exit code 0.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")

TAGS = {
    "temperature": "D100:float32",
    "pressure": "D102:int32",
    "running": "CIO 0.00",
    "alarm": "CIO 0.01",
    "batch": "D110:string:8",
}


async def main(urls: list[str], interval: float, duration: float | None) -> None:
    async with anyio.create_task_group() as tg:
        tg.start_soon(stop_on_signals, tg.cancel_scope)
        await poll(urls, interval, duration)
        tg.cancel_scope.cancel()


async def stop_on_signals(scope: anyio.CancelScope) -> None:
    """SIGINT or SIGTERM: stop polling, close the sessions, exit 0."""
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for signum in signals:
            print(f"stopping on {signal.Signals(signum).name}", file=sys.stderr, flush=True)
            scope.cancel()
            return


async def poll(urls: list[str], interval: float, duration: float | None) -> None:
    async with (
        aiofins.Pool(timeout=0.5, retries=1, read_only=True) as pool,
        aiofins.Poller(pool, changes_only=True) as poller,
    ):
        for i, url in enumerate(urls):
            poller.add_group(f"plc{i}", url, TAGS, interval=interval)
        with anyio.move_on_after(duration if duration else float("inf")):
            async for snap in poller:
                print(
                    json.dumps(
                        {
                            "plc": snap.group,
                            "scan": snap.scan,
                            "time": snap.timestamp,
                            "changed": {
                                n: [r.value, r.quality.value] for n, r in snap.readings.items()
                            },
                        }
                    ),
                    flush=True,
                )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("urls", nargs="*", default=[PLC_URL], help="PLCs (default: $PLC_URL)")
    parser.add_argument("--interval", type=float, default=0.2, help="seconds between scans")
    parser.add_argument("--duration", type=float, help="seconds to run (default: until stopped)")
    args = parser.parse_args()
    anyio.run(main, args.urls, args.interval, args.duration)
