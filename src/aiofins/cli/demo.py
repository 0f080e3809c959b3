"""``aiofins demo``: a virtual PLC in-process, a simulated process writing to it, live polling.

Starts the simulator on a free loopback UDP port, runs a small "process" that writes a counter,
a temperature (float32), a pressure (int32) and a few status bits through FINS every 100 ms,
and polls a tag list through the pool, redrawing a table of the values with their quality.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import TextIO

import anyio

from ..connection import connect
from ..poller import Poller, Snapshot
from ..pool import Pool
from ..simulator.plc import VirtualPLC
from ..simulator.runner import run_simulator

DEMO_TAGS: dict[str, str] = {
    "counter": "D0:uint16",
    "temperature": "D100:float32",
    "pressure": "D102:int32",
    "batch": "D110:string:8",
    "running": "CIO 0.00",
    "alarm": "CIO 0.01",
    "timer_pv": "T0",
}


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "demo",
        help="start a virtual PLC in-process and show live polled values",
        description="Start a virtual PLC in-process, write a simulated process into it and "
        "show a live table of polled values (no PLC needed).",
    )
    p.add_argument("--duration", type=float, default=10.0, help="seconds to run (default 10)")
    p.add_argument("--interval", type=float, default=0.5, help="poll interval in seconds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    anyio.run(demo, args.duration, args.interval)
    return 0


async def _process(url: str, stop: anyio.Event) -> None:
    """A pretend machine: writes changing values into the virtual PLC over FINS."""
    async with connect(url) as plc:
        await plc.write_value("D110", "LOT-0042", "string:8")
        tick = 0
        while not stop.is_set():
            await plc.write("D0", [tick & 0xFFFF])
            await plc.write_value("D100", 60.0 + 15.0 * math.sin(tick / 10), "float32")
            await plc.write_value("D102", 101_325 + 40 * tick, "int32")
            await plc.write("CIO 0.00", [1, 1 if (tick // 20) % 2 else 0])
            await plc.write("T0", [tick % 1000])
            tick += 1
            with anyio.move_on_after(0.1):
                await stop.wait()


def _render(snap: Snapshot, url: str, out: TextIO, live: bool) -> None:
    lines = [
        f"aiofins demo — virtual PLC at {url} — scan {snap.scan} ({snap.duration * 1000:.1f} ms)",
        "",
        f"{'tag':<12} {'address':<16} {'value':>16}  quality",
        f"{'-' * 12} {'-' * 16} {'-' * 16}  -------",
    ]
    for name, spec in DEMO_TAGS.items():
        reading = snap.readings[name]
        value = reading.value
        text = f"{value:.2f}" if isinstance(value, float) else str(value)
        lines.append(f"{name:<12} {spec:<16} {text:>16}  {reading.quality.value}")
    if live:
        out.write("\x1b[H\x1b[2J" + "\n".join(lines) + "\n")
    else:
        out.write("\n".join(lines) + "\n\n")
    out.flush()


async def demo(duration: float = 10.0, interval: float = 0.5, out: TextIO | None = None) -> int:
    """Run the demo; returns the number of snapshots shown."""
    stream = out or sys.stdout
    live = stream.isatty()
    plc = VirtualPLC()
    shown = 0
    async with run_simulator(plc, udp=("127.0.0.1", 0)) as sim:
        url = f"udp://127.0.0.1:{sim.udp_port}"
        stop = anyio.Event()
        async with anyio.create_task_group() as tg:
            tg.start_soon(_process, url, stop)
            deadline = anyio.current_time() + duration
            async with Pool() as pool, Poller(pool) as poller:
                poller.add_group("demo", url, DEMO_TAGS, interval=interval)
                with anyio.move_on_after(duration):
                    async for snap in poller:
                        _render(snap, url, stream, live)
                        shown += 1
                        if anyio.current_time() >= deadline:
                            break
            stop.set()
    stream.write(f"done: {shown} scans of {len(DEMO_TAGS)} tags.\n")
    return shown
