"""The client under trio: count the parts passing a sensor and how long each one blocked it.

aiofins runs on anyio, so the same code runs under asyncio (``anyio.run(main)``) and trio
(``anyio.run(main, backend="trio")``; ``pip install trio``). Fast polling of one bit, edges
detected in Python: for pulses longer than the interval (a check of a PLC's own counter, or
of a conveyor's gaps), not a replacement for a counter in the PLC program.

    python examples/trio_counter.py --seconds 10
    PLC_URL=udp://192.168.250.1 python examples/trio_counter.py --bit "CIO 1.05"
"""

from __future__ import annotations

import argparse
import os

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")


async def count(bit: str, seconds: float, interval: float) -> int:
    parts = 0
    since = 0.0  # when the part in front of the sensor arrived
    async with aiofins.connect(PLC_URL, timeout=1.0, read_only=True) as plc:
        last = await plc.read_bit(bit)
        print(f"counting parts on {bit} for {seconds:g} s", flush=True)
        with anyio.move_on_after(seconds):
            while True:
                now = await plc.read_bit(bit)
                if now and not last:
                    parts += 1
                    since = anyio.current_time()
                    print(f"part {parts} in", flush=True)
                elif last and not now and parts:
                    print(
                        f"part {parts} out after {anyio.current_time() - since:.2f} s", flush=True
                    )
                last = now
                await anyio.sleep(interval)
    print(f"{parts} parts in {seconds:g} s")
    return parts


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bit", default="CIO 0.00", help="the sensor's input bit")
    parser.add_argument("--seconds", type=float, default=5.0, help="how long to count")
    parser.add_argument("--interval", type=float, default=0.02, help="seconds between reads")
    args = parser.parse_args()
    anyio.run(count, args.bit, args.seconds, args.interval, backend="trio")
