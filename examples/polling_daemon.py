"""A polling daemon: scan tag lists on several PLCs and print changes as JSON lines.

    python examples/polling_daemon.py                      # against two embedded virtual PLCs
    python examples/polling_daemon.py udp://10.0.0.5 udp://10.0.0.6

Each PLC is one scan group with its own interval; a slow or dead PLC does not delay the others
and its tags turn STALE (the last good value kept, with its timestamp; tags never read are
ERROR). Ctrl-C (SIGINT) or SIGTERM (as systemd and Docker stop a service) ends it cleanly:
sessions closed, exit code 0.
"""

from __future__ import annotations

import json
import signal
import sys
from contextlib import AsyncExitStack

import anyio

import aiofins
from aiofins.simulator import VirtualPLC, run_simulator

TAGS = {
    "temperature": "D100:float32",
    "pressure": "D102:int32",
    "running": "CIO 0.00",
    "alarm": "CIO 0.01",
    "batch": "D110:string:8",
}


async def main(urls: list[str], duration: float | None) -> None:
    async with anyio.create_task_group() as tg:
        tg.start_soon(stop_on_signals, tg.cancel_scope)
        await poll(urls, duration)
        tg.cancel_scope.cancel()


async def stop_on_signals(scope: anyio.CancelScope) -> None:
    """SIGINT or SIGTERM: stop polling, close the sessions, exit 0."""
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for signum in signals:
            print(f"stopping on {signal.Signals(signum).name}", file=sys.stderr, flush=True)
            scope.cancel()
            return


async def poll(urls: list[str], duration: float | None) -> None:
    async with AsyncExitStack() as stack:
        if not urls:  # no PLC given: run two virtual ones
            for _ in range(2):
                sim = await stack.enter_async_context(
                    run_simulator(VirtualPLC(), udp=("127.0.0.1", 0))
                )
                urls.append(f"udp://127.0.0.1:{sim.udp_port}")
        pool = await stack.enter_async_context(aiofins.Pool(timeout=0.5, retries=1))
        poller = await stack.enter_async_context(aiofins.Poller(pool, changes_only=True))
        for i, url in enumerate(urls):
            poller.add_group(f"plc{i}", url, TAGS, interval=0.2)
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
    args = sys.argv[1:]
    seconds = None
    if args and args[0].startswith("--duration="):
        seconds = float(args.pop(0).split("=", 1)[1])
    anyio.run(main, args, seconds)
